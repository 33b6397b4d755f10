"""Output safety: the one place where helmet-anc writes files and output folders.

Three rules for every output (issue 12, "Data loss and overwrites"):

* checked first, before any computation: the folder exists and is writable, the
  target is not a folder, it is not one of the command's inputs, and an existing
  file there is ours (a helmet-anc format tag) unless the user says ``--force``;
* written atomically: a temporary file beside the target, renamed over it, so a
  failure or Ctrl-C leaves the previous file (or none) and no partial file;
* an output folder is only ever written when it is new, or holds nothing but a
  previous output proved by our manifest (format tag, file list, SHA-256 of each
  file), or with ``--force``; and even then only files a manifest of ours lists are
  removed. Nothing else in a folder is ever deleted.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Iterable

from .errors import HelmetAncError

__all__ = ["OutputRefused", "atomic_write", "atomic_write_bytes", "atomic_write_text", "check_output_directory",
           "check_output_file", "check_output_tree", "foreign_files", "is_ours", "publish_tree", "read_manifest",
           "read_tree_manifest", "sha256_text", "staged_directory", "staged_output_tree", "tree_manifest_text",
           "write_output_directory"]

# Every JSON file helmet-anc writes carries a "format" beginning with this tag.
FORMAT_PREFIX = "helmet-anc/"
# The suffix of the temporary files; nothing else in the project uses it.
PARTIAL = ".partial"
# First line of the (gamma, order) grid table written beside a model (sysid.estimation.grid.GridResult.to_csv).
GRID_TABLE_HEADER = b"gamma,order,stable,rms,chosen"


class OutputRefused(HelmetAncError):
    """An output location cannot or must not be written (exists and is not ours, is an input, is read-only)."""


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _default_mode(folder: bool = False) -> int:
    # mkstemp/mkdtemp create private entries (0600/0700); give the result the mode an
    # ordinary open()/mkdir() would.
    umask = os.umask(0)
    os.umask(umask)
    return (0o777 if folder else 0o666) & ~umask


def atomic_write(path: str | os.PathLike, write: Callable[[Path], None]) -> Path:
    """Create ``path`` by calling ``write(temporary_path)`` and renaming the result over ``path``.

    ``write`` must create the temporary file (e.g. ``scipy.io.savemat``); on any
    exception, KeyboardInterrupt included, the temporary file is removed and a
    previous ``path`` is left as it was. The new file gets the ordinary mode
    (0666 less the umask), whatever mode ``write`` created it with.
    """
    path = Path(path)
    folder = _folder(path)
    if not folder.is_dir():
        raise OutputRefused(f"{path}: folder {folder} does not exist")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=PARTIAL, dir=folder)
    except OSError as exc:
        raise OutputRefused(f"{path}: cannot write in {folder} ({exc.strerror})") from None
    os.close(fd)
    try:
        write(Path(tmp))
        os.chmod(tmp, _default_mode())
        os.replace(tmp, path)
    except OSError as exc:
        _remove(tmp)
        raise OutputRefused(f"{path}: cannot write ({exc.strerror or exc})") from None
    except BaseException:
        _remove(tmp)
        raise
    return path


def _remove(path) -> None:
    try:
        os.unlink(path)
    except FileNotFoundError:
        pass


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write(path, lambda tmp: tmp.write_bytes(data))


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write UTF-8 ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def sha256_text(text: str | bytes) -> str:
    """SHA-256 hex digest of a file's content (text as UTF-8)."""
    return hashlib.sha256(text.encode("utf-8") if isinstance(text, str) else text).hexdigest()


def is_ours(path: Path) -> bool:
    """True when ``path`` is a file helmet-anc wrote: a JSON object whose "format" is one of ours, an
    HTML report with our generator tag, a grid table, or a MATLAB export holding our format tag."""
    try:
        head = path.read_bytes()[:1 << 20]
    except OSError:
        return False
    if path.suffix == ".json":
        try:
            data = json.loads(head.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            return False
        return isinstance(data, dict) and str(data.get("format", "")).startswith(FORMAT_PREFIX)
    if path.suffix in (".html", ".htm"):
        return b'name="generator" content="helmet-anc' in head
    if path.suffix == ".csv":
        return head.startswith(GRID_TABLE_HEADER)
    if path.suffix == ".mat":
        return _mat_format(path).startswith(FORMAT_PREFIX)
    return False


def _mat_format(path: Path) -> str:
    import scipy.io

    try:
        value = scipy.io.loadmat(path, variable_names=["format"]).get("format")
    except Exception:  # scipy raises many types on files that are not MAT files; none of them is ours
        return ""
    try:
        return str(value.reshape(-1)[0]) if value is not None else ""
    except (AttributeError, IndexError):
        return ""


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return a.resolve() == b.resolve()


def check_output_file(path: str | os.PathLike, inputs: Iterable = (), force: bool = False,
                      option: str = "-o", ours: Callable[[Path], bool] = is_ours) -> Path:
    """Check an output file before any work is done; return it as a Path.

    Refused (OutputRefused, one line naming ``option``): a folder; a missing or
    read-only folder; one of ``inputs`` (same file by ``os.path.samefile``); an
    existing file that ``ours`` does not recognise, unless ``force``.
    """
    target = Path(path)
    folder = _folder(target)
    if target.is_dir():
        raise OutputRefused(f"{option} {target}: is a folder; give a file name")
    if not folder.is_dir():
        raise OutputRefused(f"{option} {target}: folder {folder} does not exist")
    for source in inputs:
        if source is not None and Path(source).exists() and target.exists() and _same_file(target, Path(source)):
            raise OutputRefused(f"{option} {target}: is an input of this command; give another output name")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputRefused(f"{option} {target}: folder {folder} is not writable")
    if target.exists():
        if not os.access(target, os.W_OK) and not os.access(folder, os.W_OK):
            raise OutputRefused(f"{option} {target}: file is not writable")
        if not force and not ours(target):
            raise OutputRefused(f"{option} {target}: exists and was not written by helmet-anc; "
                                "choose another name or add --force to replace it")
    return target


# -- output folders -------------------------------------------------------------

def read_manifest(folder: Path, manifest_name: str, format_tag: str) -> dict | None:
    """The ``{file name: sha256}`` list of our manifest in ``folder``, or None when there is none of ours."""
    try:
        data = json.loads((folder / manifest_name).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if data.get("format") != format_tag or not isinstance(files, dict):
        return None
    if not all(isinstance(k, str) and isinstance(v, str) and "/" not in k and k not in ("", ".", "..")
               for k, v in files.items()):
        return None
    return files


def _previous_output(folder: Path, manifest_name: str, format_tag: str) -> tuple[dict | None, list[str]]:
    """Our previous manifest's file list, and what in ``folder`` that output does not account for."""
    listed = read_manifest(folder, manifest_name, format_tag)
    present = sorted(p.name for p in folder.iterdir())
    if listed is None:
        return None, present
    foreign = [name for name in present if name != manifest_name and name not in listed]
    for name, digest in listed.items():
        file = folder / name
        if file.is_file() and not file.is_symlink() and sha256_text(file.read_bytes()) != digest:
            foreign.append(name)  # edited since we wrote it: the user's now
    return listed, foreign


def check_output_directory(outdir: str | os.PathLike, manifest_name: str, format_tag: str, force: bool = False,
                           option: str = "-o") -> Path:
    """Check an output folder before any work (see the module docstring); return it as a Path."""
    outdir = Path(outdir)
    parent = _folder(outdir)
    if outdir.exists() and not outdir.is_dir():
        raise OutputRefused(f"{option} {outdir}: exists and is not a folder")
    if not outdir.exists():
        if not parent.is_dir():
            raise OutputRefused(f"{option} {outdir}: parent folder {parent} does not exist")
        if not os.access(parent, os.W_OK | os.X_OK):
            raise OutputRefused(f"{option} {outdir}: parent folder {parent} is not writable")
        return outdir
    if not os.access(outdir, os.W_OK | os.X_OK):
        raise OutputRefused(f"{option} {outdir}: folder is not writable")
    listed, foreign = _previous_output(outdir, manifest_name, format_tag)
    if foreign and not force:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        what = "holds files helmet-anc did not write" if listed is None else "holds files not in our manifest"
        raise OutputRefused(f"{option} {outdir}: {what} ({shown}); give a new folder, "
                            "or --force to write beside them (only files our manifest lists are removed)")
    return outdir


class staged_directory:
    """Context manager: a temporary folder beside ``final`` that becomes ``final`` on success.

    ``with staged_directory(final) as staging: ...`` fills ``staging``; on normal
    exit it is renamed to ``final`` (which must not exist: if it appeared
    meanwhile, e.g. another process built the same cache entry, the staging folder
    is dropped). On any exception the staging folder is removed.
    """

    def __init__(self, final: str | os.PathLike):
        self.final = Path(final)
        self.staging: Path | None = None

    def __enter__(self) -> Path:
        parent = _folder(self.final)
        try:
            self.staging = Path(tempfile.mkdtemp(prefix=f".{self.final.name}.", suffix=PARTIAL, dir=parent))
        except OSError as exc:
            raise OutputRefused(f"{self.final}: cannot write in {parent} ({exc.strerror})") from None
        return self.staging

    def __exit__(self, kind, value, traceback) -> bool:
        if kind is None:
            try:
                os.chmod(self.staging, _default_mode(folder=True))
                os.replace(self.staging, self.final)
                return False
            except OSError:
                if not self.final.is_dir():
                    shutil.rmtree(self.staging, ignore_errors=True)
                    raise OutputRefused(f"{self.final}: cannot write") from None
        shutil.rmtree(self.staging, ignore_errors=True)
        return False


def write_output_directory(outdir: str | os.PathLike, files: dict[str, str | bytes], manifest_name: str,
                           format_tag: str, force: bool = False, option: str = "-o") -> Path:
    """Write ``files`` (names -> content; the manifest ``manifest_name`` among them) as ``outdir``.

    A new ``outdir`` appears complete or not at all. An existing one (allowed by
    :func:`check_output_directory`) gets each file atomically, the manifest last;
    files the previous manifest listed and the new output does not are removed,
    nothing else. On Ctrl-C or an error no temporary file is left.
    """
    outdir = check_output_directory(outdir, manifest_name, format_tag, force, option)
    if manifest_name not in files:
        raise ValueError(f"the files to write must include the manifest {manifest_name}")
    if not outdir.exists():
        with staged_directory(outdir) as staging:
            for name, content in files.items():
                (staging / name).write_bytes(content.encode("utf-8") if isinstance(content, str) else content)
                os.chmod(staging / name, _default_mode())
        return outdir
    previous = read_manifest(outdir, manifest_name, format_tag) or {}
    for name, content in files.items():
        if name != manifest_name:
            atomic_write_bytes(outdir / name, content.encode("utf-8") if isinstance(content, str) else content)
    for name in previous:
        if name not in files and name != manifest_name:
            _remove(outdir / name)
    content = files[manifest_name]
    atomic_write_bytes(outdir / manifest_name, content.encode("utf-8") if isinstance(content, str) else content)
    return outdir


# -- output trees (folders with sub-folders) -------------------------------------

def _tree_files(folder: Path) -> list[str]:
    """Every file (and symbolic link) under ``folder``, as sorted relative POSIX paths."""
    found = []
    for root, folders, files in os.walk(folder):
        base = Path(root)
        found.extend((base / name).relative_to(folder).as_posix() for name in files)
        # Links to folders are entries of ours or not, like files; never followed.
        found.extend((base / name).relative_to(folder).as_posix() for name in folders if (base / name).is_symlink())
    return sorted(found)


def read_tree_manifest(folder: Path, manifest_name: str, format_tag: str) -> dict | None:
    """The ``{relative path: sha256}`` list of our manifest of a folder tree, or None when there is none of ours."""
    try:
        data = json.loads((Path(folder) / manifest_name).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    files = data.get("files") if isinstance(data, dict) else None
    if data.get("format") != format_tag or not isinstance(files, dict):
        return None
    for name, digest in files.items():
        parts = name.split("/") if isinstance(name, str) else [""]
        if not isinstance(digest, str) or name.startswith("/") or any(p in ("", ".", "..") for p in parts):
            return None
    return files


def foreign_files(folder: Path, manifest_name: str, format_tag: str,
                  ours: Callable[[Path], bool] | None = None) -> tuple[dict, list[str]]:
    """Our manifest's file list for the tree ``folder`` ({} when none), and the files it does not account for.

    A file is ours when the manifest lists it with its current SHA-256 (edited since: the
    user's now), or, not listed, when ``ours(path)`` says so (e.g. a format tag).
    """
    listed = read_tree_manifest(folder, manifest_name, format_tag) or {}
    foreign = []
    for name in _tree_files(folder):
        path = folder / name
        if name == manifest_name and listed:
            continue
        if name in listed:
            if path.is_symlink() or not path.is_file() or sha256_text(path.read_bytes()) != listed[name]:
                foreign.append(name)
        elif ours is None or path.is_symlink() or not ours(path):
            foreign.append(name)
    return listed, foreign


def _shown(names: list[str]) -> str:
    return ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")


def check_output_tree(outdir: str | os.PathLike, manifest_name: str, format_tag: str, force: bool = False,
                      option: str = "-o", ours: Callable[[Path], bool] | None = None) -> Path:
    """Check an output folder tree before any work: new, or holding only our previous output, or ``force``.

    As :func:`check_output_directory`, for a folder with sub-folders; with ``force``
    the files that are not ours stay where they are and are never replaced
    (:func:`publish_tree` refuses to write over one).
    """
    outdir = Path(outdir)
    if not outdir.exists() or not outdir.is_dir():
        return check_output_directory(outdir, manifest_name, format_tag, force, option)
    if not os.access(outdir, os.W_OK | os.X_OK):
        raise OutputRefused(f"{option} {outdir}: folder is not writable")
    listed, foreign = foreign_files(outdir, manifest_name, format_tag, ours)
    if foreign and not force:
        what = "holds files not in our manifest" if listed else "holds files helmet-anc did not write"
        raise OutputRefused(f"{option} {outdir}: {what} ({_shown(foreign)}); give a new folder, or --force to "
                            "write beside them (they are never replaced or removed)")
    return outdir


def tree_manifest_text(folder: Path, format_tag: str, exclude=()) -> str:
    """Our manifest of every file under ``folder`` (relative path -> SHA-256) but ``exclude``, as JSON text."""
    files = {name: sha256_text((folder / name).read_bytes()) for name in _tree_files(folder)
             if name not in exclude and not (folder / name).is_symlink()}
    return json.dumps({"format": format_tag, "files": files}, indent=2, sort_keys=True) + "\n"


def publish_tree(staging: Path, outdir: Path, manifest_name: str, format_tag: str, option: str = "-o",
                 ours: Callable[[Path], bool] | None = None) -> Path:
    """Move the finished tree ``staging`` to ``outdir``, with our manifest of it; return ``outdir``.

    A new ``outdir`` is the renamed ``staging``: complete or absent. Into an existing
    one (allowed by :func:`check_output_tree`), each file is renamed over its
    namesake, the manifest last; files the previous manifest listed and the new tree
    does not are removed; a file that is not ours is never replaced (OutputRefused
    before anything moves) and nothing else is touched.
    """
    (staging / manifest_name).write_text(tree_manifest_text(staging, format_tag, exclude=(manifest_name,)))
    if not outdir.exists():
        try:
            os.replace(staging, outdir)
        except OSError as exc:
            raise OutputRefused(f"{option} {outdir}: cannot write ({exc.strerror or exc})") from None
        return outdir
    previous, foreign = foreign_files(outdir, manifest_name, format_tag, ours)
    new = _tree_files(staging)
    clash = sorted(set(foreign) & set(new))
    if clash:
        raise OutputRefused(f"{option} {outdir}: would replace files helmet-anc did not write ({_shown(clash)}); "
                            "move them, or give a new folder; nothing was written")
    for name in new:
        if name != manifest_name:
            (outdir / name).parent.mkdir(parents=True, exist_ok=True)
            os.replace(staging / name, outdir / name)
    for name in previous:
        if name not in new and name not in foreign:
            _remove(outdir / name)
    os.replace(staging / manifest_name, outdir / manifest_name)
    shutil.rmtree(staging, ignore_errors=True)
    return outdir


class staged_output_tree:
    """Context manager: build an output folder tree in a staging folder, then publish it.

    ``with staged_output_tree(outdir, "manifest.json", tag, force) as work: ...`` checks
    ``outdir`` first (:func:`check_output_tree`), yields an empty staging folder beside
    it to fill, and on normal exit publishes it (:func:`publish_tree`). On any
    exception, Ctrl-C included, the staging folder is removed and ``outdir`` is as it was.
    """

    def __init__(self, outdir: str | os.PathLike, manifest_name: str, format_tag: str, force: bool = False,
                 option: str = "-o"):
        self.outdir = check_output_tree(outdir, manifest_name, format_tag, force, option)
        self.manifest_name, self.format_tag, self.option = manifest_name, format_tag, option
        self.staging: Path | None = None

    def __enter__(self) -> Path:
        parent = _folder(self.outdir)
        try:
            self.staging = Path(tempfile.mkdtemp(prefix=f".{self.outdir.name}.", suffix=PARTIAL, dir=parent))
        except OSError as exc:
            raise OutputRefused(f"{self.option} {self.outdir}: cannot write in {parent} ({exc.strerror})") from None
        os.chmod(self.staging, _default_mode(folder=True))
        return self.staging

    def __exit__(self, kind, value, traceback) -> bool:
        try:
            if kind is None:
                publish_tree(self.staging, self.outdir, self.manifest_name, self.format_tag, self.option)
        finally:
            shutil.rmtree(self.staging, ignore_errors=True)
        return False
