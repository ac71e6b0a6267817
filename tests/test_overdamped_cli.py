"""``jamflow compress / shear / drive``: outputs follow the flow schema and the packing contract."""

from __future__ import annotations

import numpy as np
import xarray as xr

from jamflow.cli import main
from jamflow.io import read_packing


def test_compress_shear_drive_cli(tmp_path):
    rsa, comp, c75 = tmp_path / "rsa.nc", tmp_path / "comp.nc", tmp_path / "c75.nc"
    assert main(["init", str(rsa), "--d", "2", "--n", "24", "--phi", "0.5", "--dispersity", "bi", "--seed", "4", "--quiet"]) == 0
    assert main(["compress", str(rsa), str(comp), "--phi", "0.75", "--final", str(c75), "--quiet",
                 "--step-drift", "1e-7", "--drift-tol", "1e-6"]) == 0
    start = read_packing(c75)
    assert start.packing_fraction == np.float64(start.packing_fraction)
    assert abs(start.packing_fraction - 0.75) < 1e-12
    out, fin, ck = tmp_path / "shear.nc", tmp_path / "final.nc", tmp_path / "ck.nc"
    assert main(["shear", str(c75), str(out), "--strain", "0.01", "--final", str(fin), "--snapshots", "2",
                 "--checkpoint", str(ck), "--sync-every", "50", "--quiet"]) == 0
    ds = xr.load_dataset(out)
    for name in ("shear_stress", "pressure", "packing_fraction", "kappa", "n_contacts", "z_bar", "volume",
                 "constraint_error", "event_strain", "event_time", "event_i", "event_j", "event_kind"):
        assert name in ds and "units" in ds[name].attrs and "long_name" in ds[name].attrs, name
    assert ds.attrs["mode"] == "shear" and ds.attrs["N"] == 24 and ds.attrs["d"] == 2
    assert ds.strain.values[-1] == np.float64(0.01) or abs(ds.strain.values[-1] - 0.01) < 1e-12
    assert np.all(np.isnan(ds.kappa.values))
    assert np.all(ds.event_i.values < ds.event_j.values)
    final = read_packing(fin)
    assert final.contacts is not None and np.all(final.force > 0)
    snaps = xr.load_dataset(tmp_path / "shear.snapshots.nc")
    assert snaps.sizes["snapshot"] == 3
    assert int(snaps.snapshot_contact_count.sum()) == snaps.sizes["snapshot_contact"]
    # fixed pressure and self-propelled drive
    outp = tmp_path / "shear_p.nc"
    assert main(["shear", str(c75), str(outp), "--strain", "0.005", "--pressure", "3", "--quiet"]) == 0
    dp = xr.load_dataset(outp)
    assert dp.attrs["mode"] == "shear_fixed_pressure"
    assert np.allclose(dp.pressure.values, 3.0, rtol=1e-9)
    outd = tmp_path / "drive.nc"
    assert main(["drive", str(c75), str(outd), "--time", "0.02", "--self-propelled", "1", "--seed", "3", "--quiet"]) == 0
    assert xr.load_dataset(outd).attrs["mode"] == "drive"
    # a bad target is one clear error, exit 1
    assert main(["compress", str(c75), str(tmp_path / "bad.nc"), "--phi", "0.5", "--quiet"]) == 1
