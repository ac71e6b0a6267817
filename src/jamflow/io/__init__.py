"""Reading and writing: netCDF datasets (atomic), CALiPPSO ``.dat``, extended XYZ and GSD.

This is the only library package that touches files.
"""

from .dataset import (
    DATASET_KINDS,
    atomic_file,
    check_output_paths,
    dataset_kind,
    file_body_kind,
    file_kind,
    new_dataset_attrs,
    read_dataset,
    read_packing,
    write_dataset,
    write_packing,
    write_table,
)
from .formats import gsd_types, read_dat, size_classes, write_dat, write_gsd, write_xyz
from .pool import parse_point, pool_datasets

__all__ = [
    "DATASET_KINDS",
    "atomic_file",
    "check_output_paths",
    "dataset_kind",
    "file_body_kind",
    "file_kind",
    "gsd_types",
    "new_dataset_attrs",
    "parse_point",
    "pool_datasets",
    "read_dat",
    "read_dataset",
    "read_packing",
    "size_classes",
    "write_dat",
    "write_dataset",
    "write_gsd",
    "write_packing",
    "write_table",
    "write_xyz",
]
