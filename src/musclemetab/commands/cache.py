"""``musclemetab cache``: where the package cache is, what it holds, and clearing it."""

from __future__ import annotations

__all__ = ["add_parser", "run"]


def add_parser(sub) -> None:
    from ..cache import CACHE_FOLDERS

    p = sub.add_parser(
        "cache",
        help="the package cache: its folders, entries and size; --clear deletes the entries",
        description=(
            "Print the folder of the package cache ($MUSCLEMETAB_CACHE, default ~/.cache/musclemetab) and, "
            "for each of its folders, what it keeps, how many entries and how many MB. With --clear, delete the "
            "entries (every folder's, or those of --folders): they are computed again when next needed. Only "
            "files named as the package names its entries are deleted; any other file in those folders stays."
        ),
    )
    p.add_argument("--clear", action="store_true", help="delete the entries")
    p.add_argument("--folders", nargs="+", choices=tuple(CACHE_FOLDERS), metavar="NAME",
                   help=f"only these folders ({', '.join(CACHE_FOLDERS)}); default all")
    p.set_defaults(func=run)


def run(args) -> int:
    """Run ``musclemetab cache`` (``args`` from :func:`add_parser`)."""
    from ..cache import CACHE_FOLDERS, cache_root, cache_usage, clear_cache
    from ..errors import OptionError

    root = cache_root()
    if root.exists() and not root.is_dir():
        raise OptionError(f"the package cache {root} is a file, not a folder: set MUSCLEMETAB_CACHE to a folder")
    names = list(dict.fromkeys(args.folders or CACHE_FOLDERS))
    if args.clear:
        removed = clear_cache(names)
        entries, size = sum(u.entries for u in removed), sum(u.size_bytes for u in removed)
        print(f"cache: deleted {entries} entries ({size / 1e6:.1f} MB) from {root} "
              f"({', '.join(f'{u.name} {u.entries}' for u in removed)})")
        return 0
    usage = cache_usage(names)
    print(f"cache: {root}{'' if root.is_dir() else ' (not created yet)'}")
    width = max(len("folder"), *(len(u.name) for u in usage))
    print(f"  {'folder':<{width}}  entries        MB  what it keeps")
    for u in usage:
        print(f"  {u.name:<{width}}  {u.entries:>7}  {u.size_bytes / 1e6:>8.1f}  {CACHE_FOLDERS[u.name]}")
    print(f"  {'total':<{width}}  {sum(u.entries for u in usage):>7}  {sum(u.size_bytes for u in usage) / 1e6:>8.1f}")
    return 0
