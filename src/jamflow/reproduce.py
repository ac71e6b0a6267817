"""The reproduced-figures page: every paper scene's figure and the paper's key numbers beside jamflow's.

:func:`reproduced_page` reads the outputs of the paper scenes (``results/<scene>`` at laptop
scale, ``results/<scene>-paper`` at paper scale), copies each scene's laptop figure next to
the page and writes one table per scene: quantity | paper | laptop scale | paper scale, with
sample counts and standard errors. A scene not run says so; nothing is typed in by hand
except the papers' own numbers (each with where it stands in the paper), so the page cannot
drift from the outputs: ``jamflow reproduce docs/reproduced.md`` rewrites it.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .io import read_dataset

__all__ = ["SCENES", "reproduced_page"]

#: What is reported when a scene's outputs are not there.
NOT_RUN = "not run"


def _fmt(values: np.ndarray | list[float], digits: int = 5) -> str:
    """``mean ± standard error (n)`` of finite values; one value as it is."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return "no finite value"
    if v.size == 1:
        return f"{v[0]:.{digits}g} (1 sample)"
    return f"{v.mean():.{digits}g} ± {v.std(ddof=1) / np.sqrt(v.size):.2g} ({v.size} samples)"


def _with_err(value: float, err: float, n: int | None = None, digits: int = 5) -> str:
    extra = f" ({n} samples)" if n is not None else ""
    return f"{value:.{digits}g} ± {err:.2g}{extra}" if np.isfinite(err) else f"{value:.{digits}g}{extra}"


def _checks(root: Path, pattern: str) -> list[dict]:
    return [json.loads(p.read_text()) for p in sorted(root.glob(pattern))]


def _study(root: Path, name: str):
    path = root / "studies" / f"{name}.nc"
    if not path.is_file():
        raise FileNotFoundError(path)
    return read_dataset(path)


# --- extractors: root -> formatted value --------------------------------------------------

def _table1(kappa: float, column: str) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        ds = read_dataset(next((root / "studies" / "jamming-table").glob("*.nc")))
        if not np.any(np.isclose(ds["kappa"].values, kappa)):
            return f"kappa = {kappa:g} not in this scale"
        k = int(np.argmin(abs(ds["kappa"].values - kappa)))
        n = int(ds["n_samples"].values[k])
        if column == "LS":
            return _with_err(float(ds["phi_J_LS"].values[k]), float(ds["phi_J_LS_err"].values[k]), n)
        p = int(np.argmin(abs(np.log10(ds["p_target"].values) - np.log10(float(column)))))
        return _with_err(float(ds["phi_J"].values[k, p]), float(ds["phi_J_err"].values[k, p]), n)
    return get


def _one_minus_q(p_target: float) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        ds = _study(root, "overlap-series")
        p = int(np.argmin(abs(np.log10(ds["p_target"].values) - np.log10(p_target))))
        rows = []
        for rate in np.unique(ds["growth_rate"].values) if "growth_rate" in ds.coords else [None]:
            sel = ds["growth_rate"].values == rate if rate is not None else slice(None)
            label = f"kappa = {rate:g}: " if rate is not None else ""
            rows.append(label + _fmt(ds["one_minus_Q"].values[sel, p], 3))
        return "; ".join(rows)
    return get


def _phi_j_at_max(root: Path) -> str:
    ds = _study(root, "overlap-series")
    rows = []
    for rate in np.unique(ds["growth_rate"].values) if "growth_rate" in ds.coords else [None]:
        sel = ds["growth_rate"].values == rate if rate is not None else slice(None)
        rows.append((f"kappa = {rate:g}: " if rate is not None else "") + _fmt(ds["phi_J"].values[sel, -1]))
    return "; ".join(rows)


def _exponent(study: str) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        ds = _study(root, study)
        k = int(np.argmax(ds["p_target"].values)) if "p_target" in ds.coords else -1
        n = int(ds["attr_n_samples"].values[k]) if "attr_n_samples" in ds else None
        return _with_err(float(ds["attr_fit_exponent"].values[k]), float(ds["attr_fit_exponent_err"].values[k]), n, 3)
    return get


def _isostatic(pattern: str) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        checks = _checks(root, pattern)
        if not checks:
            raise FileNotFoundError(root / pattern)
        iso = sum(bool(c.get("isostatic")) for c in checks)
        return f"{iso} of {len(checks)} packings at N_c = N_c^0 (N_c {min(c['n_contacts'] for c in checks)}" \
               f"-{max(c['n_contacts'] for c in checks)})"
    return get


def _calippso_packings(root: Path) -> str:
    rows = []
    for path in sorted(root.glob("import/*/*/calippso.nc")):
        a = read_dataset(path).attrs
        rows.append(f"d = {a['d']}: phi_J = {a['phi_J']:.6f}, N_c = {a['n_contacts']} "
                    f"(d (N_s - 1) + 1 = {a['isostatic_count']})")
    if not rows:
        raise FileNotFoundError(root / "import")
    return "; ".join(rows)


def _walls(root: Path) -> str:
    paths = sorted(root.glob("spheres/*/*/calippso.nc"))
    if not paths:
        raise FileNotFoundError(root / "spheres")
    attrs = [read_dataset(p).attrs for p in paths]
    iso = sum(int(a["n_contacts"]) == int(a["isostatic_count"]) for a in attrs)
    return f"{iso} of {len(attrs)} packings isostatic, phi_J {_fmt([a['phi_J'] for a in attrs])}"


def _flow(what: str) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        paths = sorted(root.glob("spheres/*/*/shear.flow-summary.nc"))
        if not paths:
            raise FileNotFoundError(root / "spheres")
        rows = []
        for path in paths:
            ds = read_dataset(path)
            point = path.parent.parent.name
            quantity = list(ds["quantity"].values) if "quantity" in ds.coords else []
            if what == "friction":
                k = quantity.index("friction")
                rows.append(f"{point}: {_with_err(float(ds['steady_mean'].values[k]), float(ds['steady_err'].values[k]), None, 3)}")
            elif what in quantity:
                k = quantity.index(what)
                rows.append(f"{point}: {_with_err(float(ds['steady_mean'].values[k]), float(ds['steady_err'].values[k]), None, 3)}")
        return "; ".join(rows)
    return get


def _flow_curve(root: Path) -> str:
    ds = read_dataset(next((root / "studies" / "flow-curve").glob("*.nc")))
    return "; ".join(f"I = {i:.3g}: mu = {_with_err(m, e, None, 3)}, phi = {_with_err(p, pe, None, 4)}"
                     for i, m, e, p, pe in zip(ds["viscous_number"].values, ds["friction"].values,
                                               ds["friction_err"].values, ds["packing_fraction"].values,
                                               ds["packing_fraction_err"].values))


def _moduli(root: Path) -> str:
    ds = read_dataset(next((root / "studies" / "chains-moduli").glob("*.nc")))
    x = ds["links_per_sphere"].values
    return "; ".join(f"n_l/N = {x[k]:.2f}: G = {_with_err(float(ds['shear_weighted'].values[k]), float(ds['shear_se'].values[k]), int(ds['n_packings'].values[k]), 3)}"
                     for k in (0, len(x) - 1))


def _survey(family: str, what: str) -> Callable[[Path], str]:
    def get(root: Path) -> str:
        ds = read_dataset(next((root / "studies" / "shape-survey").glob("*.nc")))
        fam = ds["group_family"].values
        rows = [f"A - 1 = {a - 1:.3g}: {_with_err(float(m), float(e), int(n), 4)}"
                for f, a, m, e, n in zip(fam, ds["group_asphericity"].values, ds[f"{what}_mean"].values,
                                         ds[f"{what}_sem"].values, ds["n_packings"].values) if f.startswith(family)]
        return "; ".join(rows) or f"no {family} packings"
    return get


def _quartic(root: Path) -> str:
    attrs = [read_dataset(p).attrs for p in sorted(root.glob("shapes*/*/*/*.modes.nc"))]
    if not attrs:
        raise FileNotFoundError(root)
    holds = sum(int(a["n_contacts_twice"]) == int(a["isostatic_minus_quartic"]) for a in attrs)
    return f"{holds} of {len(attrs)} packings (contacts counted twice where parallel)"


@dataclass(frozen=True)
class Row:
    """One line of a scene's table."""

    quantity: str
    paper: str
    value: Callable[[Path], str]


@dataclass(frozen=True)
class ScenePage:
    """A paper scene on the page: its figures and its rows."""

    scene: str
    title: str
    figures: tuple[str, ...]
    rows: tuple[Row, ...]


_T1 = "CALiPPSO Table I (20 samples, N = 1024)"
#: Every paper scene, with the paper's key numbers (and where each stands in the paper).
SCENES: tuple[ScenePage, ...] = (
    ScenePage("calippso-ls-check", "CALiPPSO: the authors' LS configurations jammed", (), (
        Row("phi_J and N_c of the LS examples (N = 1024)", "isostatic, N_c = d (N_s - 1) + 1 (Sec. II B)",
            _calippso_packings),)),
    ScenePage("calippso-fig3", "CALiPPSO Fig. 3: LS+CALiPPSO against p_tar", ("phi-j-series",), (
        Row("1 - Q(p_tar = 1e3)", "~0.1: about 10 % of the contacts set late (Sec. III A)", _one_minus_q(1e3)),
        Row("<phi_J> from p_max", "0.64244(20) at kappa = 3e-4 (Table I)", _phi_j_at_max))),
    ScenePage("calippso-table1", "CALiPPSO Table I: phi_J^(LS) against LS+CALiPPSO", ("jamming-table",), tuple(
        Row(f"kappa = {k}: {label}", paper, _table1(float(k), column))
        for k, values in (("3e-4", ("0.64244(20)", "0.64240(21)", "0.64244(20)")),
                          ("1e-4", ("0.64274(23)", "0.64272(22)", "0.64274(23)")),
                          ("3e-5", ("0.64314(19)", "0.64313(19)", "0.64314(19)")),
                          ("1e-5", ("0.64329(18)", "0.64328(17)", "0.64329(18)")))
        for (label, column), paper in zip((("<phi_J^(LS)>", "LS"), ("<phi_J(p_tar = 1e3)>", "1e3"),
                                           ("<phi_J(p_tar = 1e5)>", "1e5")), (f"{v} ({_T1})" for v in values)))),
    ScenePage("calippso-fig10", "CALiPPSO Fig. 10: gaps of LS snapshots and of their jammed packings",
              ("gaps-ls-vs-calippso",), (
        Row("gamma of the jammed packings (largest p_tar)", "0.41269 (mean field; Fig. 10's guide)", _exponent("gaps")),)),
    ScenePage("lerner-fig4", "Lerner et al. Fig. 4: stress against strain at fixed volume", ("stress-strain",), (
        Row("steady-state friction mu = sigma / p", "figure only (Fig. 4)", _flow("friction")),)),
    ScenePage("lerner-fig6", "Lerner et al. Fig. 6: event-driven against steepest-descent shear", ("ed-vs-sd",), ()),
    ScenePage("lerner-fig7", "Lerner et al. Fig. 7: phi and kappa at fixed pressure", ("stress-strain",), (
        Row("steady-state kappa", "fluctuates about 0 (Fig. 7)", _flow("kappa")),
        Row("steady-state phi", "figure only (Fig. 7)", _flow("packing_fraction")))),
    ScenePage("flow-curve", "Flow curve: friction and phi against the viscous number", ("flow-curve",), (
        Row("mu(I), phi(I)", "figure only (Sec. V A)", _flow_curve),)),
    ScenePage("chains-fig2", "Chains paper Fig. 2: jammed rigid trimers", ("packing",), (
        Row("contacts against the cluster isostatic count", "isostatic (Fig. 2)",
            _isostatic("linked-trimer/*/*/soft-jam.check.json")),)),
    ScenePage("chains-fig5", "Chains paper Fig. 5: moduli against added links", ("chains-moduli",), (
        Row("shear modulus G at the smallest and largest n_l / N", "figure only (Fig. 5)", _moduli),)),
    ScenePage("vanderwerf-fig3b", "VanderWerf et al. Fig. 3b: asymmetric dimers", ("packing",), (
        Row("N_c = 3N - 1 - N_rot", "isostatic (Fig. 3b, N_c = 3N - 4 with three rotators)",
            _isostatic("linked-dimer/*/*/soft-jam.check.json")),)),
    ScenePage("vanderwerf-fig5", "VanderWerf et al. Fig. 5: phi_J against A - 1", ("phi-asphericity",), (
        Row("phi_J of bidisperse disks (A = 1)", "~0.84 (Sec. III B; 0.835 in Fig. 1)", _survey("disk", "phi_J")),
        Row("phi_J of ellipses", "peak near A - 1 ~ 0.1, falls beyond (Fig. 5)", _survey("ellipse", "phi_J")))),
    ScenePage("vanderwerf-fig8", "VanderWerf et al. Fig. 8: <z> against A - 1", ("z-asphericity",), (
        Row("<z> of disks", "4 (isostatic)", _survey("disk", "z")),
        Row("<z> of circulo-lines", "below 6 for every A (hypostatic; Fig. 8)", _survey("circulo_line", "z")))),
    ScenePage("vanderwerf-fig7", "VanderWerf et al. Fig. 7: spectra of circulo-lines", ("spectra",), (
        Row("quartic-mode identity N_c = N_c^0 - N_1", "holds for every packing (Sec. III B)", _quartic),)),
    ScenePage("vanderwerf-fig10-11", "VanderWerf et al. Figs. 10-11: quartic modes against P0",
              ("quartic-pressure",), (
        Row("quartic-mode identity N_c = N_c^0 - N_1", "holds for every packing (Sec. III B)", _quartic),)),
    ScenePage("vanderwerf-fig14", "VanderWerf et al. Fig. 14: contact angles", ("contact-angles",), ()),
    ScenePage("walls", "Jamming between hard walls", ("packing",), (
        Row("N_c = d N_s + 1 (wall contacts included)", "isostatic (CALiPPSO with walls)", _walls),)),
)


def _missing(scenes: Path, scene: str, scale: str, results: Path) -> tuple[int, int]:
    """Targets of the scene at ``scale`` (its plan) that are missing under ``results``, and their number."""
    import yaml

    from .scenes import plan_scene, read_scene

    config = yaml.safe_load((scenes / f"{scene}.yaml").read_text())
    plan = plan_scene(read_scene({**config, "scale": scale}), str(results))
    # a cluster group's bundle listing is bookkeeping, not an output of the scene
    targets = [t for t in plan.targets if "/bundles/" not in t]
    return sum(not Path(t).is_file() for t in targets), len(targets)


def _cell(row: Row, root: Path, missing: tuple[int, int]) -> str:
    if not root.is_dir():
        return NOT_RUN
    if missing[0]:
        return f"incomplete ({missing[1] - missing[0]} of {missing[1]} outputs)"
    return row.value(root)


def reproduced_page(results: str | Path, out: str | Path, scenes: str | Path = "config/scenes") -> Path:
    """Write the page (markdown) and copy each scene's laptop figures beside it.

    Parameters
    ----------
    results : path-like
        The results folder holding ``<scene>`` (laptop) and ``<scene>-paper`` (paper scale).
    out : path-like
        The markdown file; figures go to ``<out stem>/`` beside it.
    scenes : path-like
        The scene files: a scale whose planned outputs are not all there is reported incomplete.
    """
    results, out, scenes = Path(results), Path(out), Path(scenes)
    figures = out.parent / out.stem
    figures.mkdir(parents=True, exist_ok=True)
    lines = ["# Reproduced figures", "",
             "Every paper scene at laptop scale (`snakemake --configfile config/scenes/<scene>.yaml`) and, where run,",
             "at paper scale (`--config scale=paper`), beside the paper's numbers. Written by",
             f"`jamflow reproduce {out.as_posix()}` from the scenes' outputs; values are means ± standard errors",
             f"over the samples stated. \"{NOT_RUN}\": the scene's outputs were not there when the page was written;",
             "\"incomplete\": some of the outputs its plan names were missing.",
             ""]
    for page in SCENES:
        laptop, paper = results / page.scene, results / f"{page.scene}-paper"
        lines += [f"## {page.title} (`{page.scene}`)", ""]
        for fig in page.figures:
            pngs = sorted((laptop / "figures").glob(f"{fig}.png")) + sorted((laptop / "figures").glob(f"{fig}_*.png"))
            for png in pngs:
                target = figures / f"{page.scene}_{png.name.replace('=', '-').replace(',', '_')}"
                shutil.copyfile(png, target)
                lines += [f"![{page.scene}: {png.stem}]({figures.name}/{target.name})", ""]
            if not pngs:
                lines += [f"Figure `{fig}`: {NOT_RUN} at laptop scale.", ""]
        if page.rows:
            lines += ["| quantity | paper | laptop scale | paper scale |", "|---|---|---|---|"]
            missing = {scale: _missing(scenes, page.scene, scale, results) if root.is_dir() else (0, 0)
                       for scale, root in (("laptop", laptop), ("paper", paper))}
            lines += [f"| {r.quantity} | {r.paper} | {_cell(r, laptop, missing['laptop'])} | "
                      f"{_cell(r, paper, missing['paper'])} |" for r in page.rows]
            lines.append("")
    out.write_text("\n".join(lines))
    return out
