"""IPOPT's linear solvers: MUMPS and SPRAL built into CasADi's IPOPT, or HSL's MA27/MA57/MA86/MA97
and Pardiso loaded by IPOPT at run time from a library the user names (option
``linear_solver_library``, environment variable :data:`LIBRARY_ENV`); :func:`check_linear_solver`
checks, before any problem is built, that IPOPT will be able to load it (the file exists, is a
shared library of this machine and exports the symbols IPOPT looks up), docs/solver.md."""

from __future__ import annotations

import ctypes
import os
import struct

from ..errors import OptionError

__all__ = ["BUILTIN_LINEAR_SOLVERS", "RUNTIME_LINEAR_SOLVERS", "LIBRARY_ENV", "LINEAR_SOLVER_SYMBOLS",
           "linear_solver_library", "exported_symbols", "check_linear_solver"]


#: IPOPT's linear solvers: built into CasADi's IPOPT, or loaded at run time from a library
#: (IPOPT option naming the library, default file name).
BUILTIN_LINEAR_SOLVERS = ("mumps", "spral")
RUNTIME_LINEAR_SOLVERS = {
    "ma27": ("hsllib", "libhsl.so"),
    "ma57": ("hsllib", "libhsl.so"),
    "ma77": ("hsllib", "libhsl.so"),
    "ma86": ("hsllib", "libhsl.so"),
    "ma97": ("hsllib", "libhsl.so"),
    "pardiso": ("pardisolib", "libpardiso.so"),
}


#: Environment variable naming the library of a run-time linear solver, for runs whose options
#: come from a study file (which may name a solver but not a library).
LIBRARY_ENV = "MUSCLEMETAB_LINEAR_SOLVER_LIBRARY"
#: Symbols the library of each run-time solver must export (IPOPT's HSL and Pardiso loaders
#: look them up); Fortran names with or without the trailing underscore.
LINEAR_SOLVER_SYMBOLS = {
    "ma27": ("ma27ad_", "ma27bd_", "ma27cd_"),
    "ma57": ("ma57ad_", "ma57bd_", "ma57cd_"),
    "ma77": ("ma77_open_d", "ma77_factor_d", "ma77_solve_d"),
    "ma86": ("ma86_analyse_d", "ma86_factor_d", "ma86_solve_d"),
    "ma97": ("ma97_analyse_d", "ma97_factor_d", "ma97_solve_d"),
    "pardiso": ("pardisoinit", "pardiso"),
}
#: Folders searched for a library given by file name only (after ``LD_LIBRARY_PATH``)
LIBRARY_FOLDERS = ("/usr/local/lib", "/usr/lib/x86_64-linux-gnu", "/usr/lib64", "/usr/lib", "/lib/x86_64-linux-gnu",
                   "/lib64", "/lib")


def linear_solver_library(name: str, library: str | None = None) -> str | None:
    """The library IPOPT loads the run-time solver ``name`` from: ``library`` (the command
    line), else the environment variable :data:`LIBRARY_ENV`, else the default file name of its
    family (``libhsl.so``, ``libpardiso.so``); ``None`` for the built-in solvers."""
    if name not in RUNTIME_LINEAR_SOLVERS:
        return None
    return library or os.environ.get(LIBRARY_ENV) or RUNTIME_LINEAR_SOLVERS[name][1]


def exported_symbols(path) -> set[str]:
    """Names of the functions and data a shared library (ELF) exports, read from its dynamic
    symbol table (``.dynsym``) without loading it; :class:`ValueError` when the file is not
    an ELF shared library."""
    with open(path, "rb") as f:
        data = f.read()
    if data[:4] != b"\x7fELF" or data[4] not in (1, 2) or data[5] not in (1, 2):
        raise ValueError("not an ELF file")
    is64, end = data[4] == 2, "<" if data[5] == 1 else ">"
    if struct.unpack_from(end + "H", data, 16)[0] != 3:  # e_type ET_DYN
        raise ValueError("not a shared library")
    if is64:
        shoff, = struct.unpack_from(end + "Q", data, 0x28)
        shentsize, shnum = struct.unpack_from(end + "HH", data, 0x3A)
        sh_fmt, sym_fmt = end + "IIQQQQIIQQ", end + "IBBHQQ"
    else:
        shoff, = struct.unpack_from(end + "I", data, 0x20)
        shentsize, shnum = struct.unpack_from(end + "HH", data, 0x2E)
        sh_fmt, sym_fmt = end + "IIIIIIIIII", end + "IIIBBH"
    sections = [struct.unpack_from(sh_fmt, data, shoff + i * shentsize) for i in range(shnum)]
    names = set()
    for sec in sections:
        if sec[1] != 11:  # SHT_DYNSYM
            continue
        offset, size, link, entsize = sec[4], sec[5], sec[6], sec[9]
        strtab = sections[link][4]
        for k in range(size // entsize if entsize else 0):
            fields = struct.unpack_from(sym_fmt, data, offset + k * entsize)
            st_name, info, shndx = (fields[0], fields[1], fields[3]) if is64 else (fields[0], fields[3], fields[5])
            if shndx == 0 or (info >> 4) not in (1, 2):  # undefined, or not global/weak
                continue
            stop = data.index(b"\0", strtab + st_name)
            names.add(data[strtab + st_name:stop].decode("utf-8", "replace"))
    return names


def _find_library(lib: str) -> str | None:
    """``lib`` when it is a path; a file name looked up in ``LD_LIBRARY_PATH`` and :data:`LIBRARY_FOLDERS`."""
    if os.sep in lib:
        return lib if os.path.isfile(lib) else None
    folders = [d for d in os.environ.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d] + list(LIBRARY_FOLDERS)
    return next((os.path.join(d, lib) for d in folders if os.path.isfile(os.path.join(d, lib))), None)


def check_linear_solver(name: str, library: str | None = None) -> None:
    """Raise :class:`OptionError` unless IPOPT can use the linear solver ``name``.

    For the solvers IPOPT loads at run time, the library (:func:`linear_solver_library`) is
    found, its dynamic symbol table read (:func:`exported_symbols`) and, only when it exports
    the solver's functions (:data:`LINEAR_SOLVER_SYMBOLS`), loaded here: a missing or foreign
    library is reported before the problem is built, and no code of a library that is not
    the solver's runs.
    """
    if name in BUILTIN_LINEAR_SOLVERS:
        if library is not None:
            raise OptionError(f"linear solver {name} is built into IPOPT; drop the linear-solver library {library!r}")
        return
    if name not in RUNTIME_LINEAR_SOLVERS:
        raise OptionError(
            f"linear solver {name!r} is unknown; choose one of "
            f"{', '.join(BUILTIN_LINEAR_SOLVERS + tuple(RUNTIME_LINEAR_SOLVERS))}"
        )
    option, _ = RUNTIME_LINEAR_SOLVERS[name]
    lib = linear_solver_library(name, library)
    what = "the HSL library (www.hsl.rl.ac.uk/ipopt)" if option == "hsllib" else "the Pardiso library"
    remedy = (f"install {what} and give its path as the linear-solver library (--linear-solver-library, or the "
              f"environment variable {LIBRARY_ENV}), or use mumps or spral")
    path = _find_library(lib)
    if path is None:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded (no such file"
                          f"{'' if os.sep in lib else ' on the library search path'}); {remedy}")
    try:
        symbols = exported_symbols(path)
    except (OSError, ValueError, IndexError, struct.error) as exc:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded (not a readable "
                          f"shared library: {exc}); {remedy}") from None
    missing = [s for s in LINEAR_SOLVER_SYMBOLS[name] if not {s, s.rstrip("_"), s + "_"} & symbols]
    if missing:
        raise OptionError(f"linear solver {name}: {lib} does not export {', '.join(missing)}, so it is not {what} "
                          f"and was not loaded; {remedy}")
    try:
        ctypes.CDLL(path)
    except OSError as exc:
        raise OptionError(f"linear solver {name}: IPOPT loads it from {lib}, which cannot be loaded ({exc}); "
                          f"{remedy}") from None
