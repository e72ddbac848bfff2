"""File input and output: OpenSim storage files, JSON objects, atomic writes."""

from .atomic import file_sha256, atomic_directory, atomic_path, atomic_write_bytes, atomic_write_text
from .jsonfile import read_json_object
from .storage import read_storage, require_columns, storage_from_arrays, write_storage

__all__ = [
    "read_storage",
    "write_storage",
    "require_columns",
    "storage_from_arrays",
    "atomic_path",
    "atomic_write_text",
    "atomic_write_bytes",
    "atomic_directory",
    "file_sha256",
    "read_json_object",
]
