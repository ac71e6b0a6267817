# Helpers of the shapes rules (workflow/rules/shapes.smk): body tags, packing paths, targets.
# Shaped 2D bodies (VanderWerf et al.): rotations, spectra, phi_J / <z> against asphericity,
# contact angles and their figures.
# A body tag is <shape>_A<asphericity> (circulo-polygon<n> for n sides), reuleaux, or disk
# (bidisperse disks of the sphere code at the same N, P0 and seeds: the A = 1 limit).


SHAPES = config.get("shapes", {})


def shape_bodies():
    """Body tags of the scene, in the order the scene lists them (disks last)."""
    tags = []
    for fam in SHAPES.get("families", []):
        name = f"{fam['shape']}{fam['sides']}" if fam["shape"] == "circulo-polygon" else fam["shape"]
        if fam["shape"] == "reuleaux":
            tags.append("reuleaux")
        else:
            tags += [f"{name}_A{a:.12g}" for a in fam["asphericities"]]
    return tags + (["disk"] if SHAPES.get("disks") else [])


def shape_pressures():
    """P0 values as path tags, ascending."""
    return [f"{p:g}" for p in sorted(SHAPES.get("pressures", []))]


def shape_packing(body, pressure, seed):
    return f"{RESULTS}/shapes/{body}/p{pressure}/seed{seed}.nc"


def shape_packings(bodies=None, pressures=None, seeds=None):
    return [
        shape_packing(b, p, s)
        for b in (bodies or shape_bodies())
        for p in (pressures or shape_pressures())
        for s in (seeds or SHAPES.get("seeds", []))
    ]


def elongated_bodies():
    """Bodies with a long axis (contact angles): ellipses and circulo-lines."""
    return [b for b in shape_bodies() if b.startswith(("ellipse_", "circulo-line_"))]


def shape_targets():
    """What a shapes scene asks for beyond its figures: the survey and, if asked, spectra and angles."""
    if not SHAPES:
        return []
    targets = [f"{RESULTS}/analysis/shape-survey.nc"]
    if SHAPES.get("modes"):
        targets += [p.replace(".nc", ".modes.nc") for p in shape_packings([b for b in shape_bodies() if b != "disk"])]
    if SHAPES.get("contact_angles"):
        targets += contact_angle_files()
    return targets


def contact_angle_files():
    return [f"{RESULTS}/analysis/contact-angles_{b}_p{p}.nc" for b in elongated_bodies() for p in shape_pressures()]


def init_shape_options(body):
    """``jamflow init-shapes`` options of a body tag."""
    if body == "reuleaux":
        return "--shape reuleaux"
    name, a = body.split("_A")
    if name.startswith("circulo-polygon"):
        return f"--shape circulo-polygon --sides {name.removeprefix('circulo-polygon')} --asphericity {a}"
    return f"--shape {name} --asphericity {a}"


def jam_start(wildcards):
    """The random start, or with pressure_chain the packing jammed at the next lower P0."""
    pressures = shape_pressures()
    k = pressures.index(wildcards.pressure)
    if SHAPES.get("pressure_chain") and k > 0:
        return shape_packing(wildcards.body, pressures[k - 1], wildcards.seed)
    return f"{RESULTS}/shapes/{wildcards.body}/init_seed{wildcards.seed}.nc"


def modes_labels(files):
    """Legend labels ``<body>,P0=<p>`` of modes files (``.../<body>/p<P0>/seed<S>.modes.nc``)."""
    return " ".join(f"{Path(f).parent.parent.name},P0={Path(f).parent.name.removeprefix('p')}" for f in files)


wildcard_constraints:
    body="(ellipse|circulo-line|circulo-polygon[0-9]+)_A[0-9.e+-]+|reuleaux|disk",
    shape_body="(ellipse|circulo-line|circulo-polygon[0-9]+)_A[0-9.e+-]+|reuleaux",
    pressure="[0-9.e+-]+",
    seed="[0-9]+",


