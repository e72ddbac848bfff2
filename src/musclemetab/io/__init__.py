"""File input and output: OpenSim storage files, JSON objects, atomic writes, optional Parquet copies."""

from .atomic import (
    atomic_directory,
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    check_inside,
    check_output_folder,
    file_sha256,
    source_path,
)
from .jsonfile import json_ready, read_json_object
from .parquet import parquet_available, write_parquet
from .storage import (
    StorageTable,
    as_table,
    check_time_stamps,
    constant_rate,
    read_storage,
    read_table,
    require_columns,
    storage_from_arrays,
    table_path,
    write_storage,
)

__all__ = [
    "source_path",
    "StorageTable",
    "read_table",
    "as_table",
    "table_path",
    "read_storage",
    "write_storage",
    "require_columns",
    "storage_from_arrays",
    "check_time_stamps",
    "constant_rate",
    "atomic_path",
    "atomic_write_text",
    "atomic_write_bytes",
    "atomic_directory",
    "file_sha256",
    "check_output_folder",
    "check_inside",
    "read_json_object",
    "json_ready",
    "parquet_available",
    "write_parquet",
]
