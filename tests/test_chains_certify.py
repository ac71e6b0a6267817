"""The chain LP of Sec. V: collective and strict jamming of linked packings."""

from __future__ import annotations

import numpy as np
import pytest

from jamflow.chains.builders import linked_packing
from jamflow.chains.certify import certify_linked
from jamflow.chains.jamming import jam_linked
from jamflow.cli import main
from jamflow.io import read_dataset, write_packing
from jamflow.minimize.onset import JammingSettings
from jamflow.models.spheres.potential import overlapping_pairs
from jamflow.protocols.certify import certify
from jamflow.protocols.initial import random_packing
from jamflow.protocols.soft_jam import jam_to_pressure


@pytest.mark.parametrize("seed", [3, 4])
def test_without_links_the_chain_lp_is_jamflow_certify(seed):
    p = jam_to_pressure(random_packing(48, 2, 0.5, "bi", seed=seed), 1e-6, force_tol=1e-12, pressure_rtol=1e-4).packing
    want = certify(p, strict=True)
    got = certify_linked(p, strict=True)
    assert got.classification == want.classification
    assert np.array_equal(got.rattler, want.rattler)


@pytest.fixture(scope="module", params=[False, True], ids=["fixed-box", "shear-stabilized"])
def trimers(request):
    start, _ = linked_packing(2, 8, "trimer", np.random.default_rng(1), phi=0.3, no_overlap=True)
    settings = JammingSettings(force_tol=1e-12, pressure_rtol=1e-2, delta_phi=1e-2)
    return request.param, jam_linked(start, 1e-3, settings=settings, shear_stabilize=request.param).packing


def test_jammed_trimers_are_collectively_jammed_and_strictly_only_when_shear_stabilized(trimers, tmp_path, capsys):
    stabilized, p = trimers
    cert = certify_linked(p, strict=True)
    assert cert.classification == ("strictly_jammed" if stabilized else "collectively_jammed")
    if not stabilized:
        # the unjamming motion strains the box: it is found by the strict LP only
        assert cert.motion_stage == "strict"
    write_packing(p, tmp_path / "p.nc")
    assert main(["certify", str(tmp_path / "p.nc"), str(tmp_path / "c.nc"), "--strict", "--soft"]) == 0
    ds = read_dataset(tmp_path / "c.nc", "chain-certificate")
    assert ds.attrs["classification"] == cert.classification
    assert f"classification  {cert.classification}" in capsys.readouterr().out


def test_a_trimer_without_contacts_is_a_rattling_cluster(trimers):
    """Shrinking one trimer's spheres frees it: counting or the LP must put it outside the backbone."""
    _, p = trimers
    D = p.diameter.copy()
    D[0:3] *= 0.5
    loose = p.evolve(diameter=D, contacts=None, force=None, rattler=None)
    pairs, _, _ = overlapping_pairs(loose.position, loose.box, loose.diameter)
    contacts = np.stack([pairs.i, pairs.j], axis=1)
    loose = loose.evolve(contacts=contacts[~loose.links.contains(contacts[:, 0], contacts[:, 1])])
    cert = certify_linked(loose, strict=False)
    assert cert.rattler[:3].all()


def test_certify_of_an_overlapping_sphere_packing_says_soft(tmp_path, capsys):
    """A soft-jam output overlaps: without --soft certify stops and names the option; with it, it runs."""
    from pathlib import Path

    src = Path(__file__).parent / "data" / "bodies" / "spheres_soft.nc"
    assert main(["certify", str(src), str(tmp_path / "c.nc")]) == 1
    err = capsys.readouterr().err
    assert "overlap by more than" in err and "written by soft-jam" in err and "--soft" in err
    assert not (tmp_path / "c.nc").exists()
    assert main(["certify", str(src), str(tmp_path / "c.nc"), "--soft", "--quiet"]) == 0
