"""CasADi functions compiled to C with gcc, cached on disk (one place for the whole package).

``build_library`` writes the C code of CasADi functions, compiles it to a shared library and
keeps it under ``$PIPELINE_CACHE_DIR`` (default ``$XDG_CACHE_HOME/pipeline``, else
``~/.cache/pipeline``)/<subdir>, named by a
key: by default the SHA-256 of the generated code, the gcc flags and the CasADi version, so
any change of the model or expression compiles anew and nothing is compiled twice. Callers
whose code generation is itself costly pass their own ``key`` and a lazy ``functions``
callable: the code is then generated only when the library is missing. A library is built under
an exclusive file lock beside it: a second process asking for it meanwhile waits and loads it
(the file itself is written atomically, ``os.replace``). While a library is compiled, or waited for,
the active progress display (:mod:`pipeline.core.progress`) shows a line ``compiling <name> ...``.

Faults: a cache folder that cannot be written falls back to a private temporary cache (with a
warning on stderr); every library has its SHA-256 in ``<library>.sha256`` beside it and is
verified before it is loaded (``dlopen`` of a truncated library crashes the process with
SIGBUS): a library that does not match is compiled again.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import hashlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path

import casadi as ca

from pipeline.core import progress
from pipeline.core.errors import SolverError

DEFAULT_FLAGS = ("-O2",)


def cache_root() -> Path:
    """``$PIPELINE_CACHE_DIR``, else ``$XDG_CACHE_HOME/pipeline``, else ``~/.cache/pipeline``."""
    env = os.environ.get("PIPELINE_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "pipeline"


_FALLBACK: list[Path] = []


def _writable_cache(cache: Path) -> Path:
    """``cache`` when it can be created and written, else a private temporary cache (warned once)."""
    try:
        cache.mkdir(parents=True, exist_ok=True)
        probe = tempfile.NamedTemporaryFile(dir=cache, prefix=".probe-", delete=True)
        probe.close()
        return cache
    except OSError as exc:
        if exc.errno not in (errno.EACCES, errno.EPERM, errno.EROFS, errno.ENOSPC, errno.ENOTDIR, errno.EEXIST):
            raise
        if not _FALLBACK:
            _FALLBACK.append(Path(tempfile.mkdtemp(prefix="pipeline-cache-")))
            print(f"warning: compiled-code cache {cache} is not writable ({exc.strerror}); "
                  f"using {_FALLBACK[0]} for this process", file=sys.stderr)
        fallback = _FALLBACK[0] / cache.name
        fallback.mkdir(parents=True, exist_ok=True)
        return fallback


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _intact(library: Path) -> bool:
    """The library exists and matches the SHA-256 stored beside it."""
    stamp = library.with_name(library.name + ".sha256")
    try:
        return library.is_file() and stamp.read_text().strip() == _sha256(library)
    except OSError:
        return False


def _generate(functions: Sequence[ca.Function], name: str) -> str:
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for function in functions:
        generator.add(function)
    return generator.dump()


def _sources(functions: Sequence[ca.Function], name: str) -> list[str]:
    """The C code of each function in a file of its own (its static helpers with it), so that the
    files compile side by side; a single function: one file, as before."""
    if len(functions) == 1:
        return [_generate(functions, name)]
    return [_generate([f], f"{name}_{f.name()}") for f in functions]


def compile_jobs() -> int:
    """gcc processes run side by side: ``$PIPELINE_JOBS``, else the cores this process may use."""
    env = os.environ.get("PIPELINE_JOBS")
    if env:
        return max(1, int(env))
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def _run_side_by_side(commands: list[list[str]], jobs: int, where: str, name: str, tmp: Path) -> None:
    """Run the gcc ``commands`` at most ``jobs`` at a time, in the given order, each starting as soon
    as a slot is free; the first failure stops the others and raises :class:`SolverError` with gcc's
    message (each process writes its messages to a file in ``tmp``: no pipe to fill)."""
    pending = list(enumerate(commands))
    running: list[tuple[subprocess.Popen[bytes], Path]] = []
    try:
        while pending or running:
            while pending and len(running) < jobs:
                k, command = pending.pop(0)
                log = tmp / f"gcc_{k}.log"
                with log.open("wb") as sink:
                    running.append((subprocess.Popen(command, stdout=sink, stderr=subprocess.STDOUT), log))
            finished = [item for item in running if item[0].poll() is not None]
            if not finished:
                time.sleep(0.02)
                continue
            for item in finished:
                running.remove(item)
                if item[0].returncode != 0:
                    message = item[1].read_text(errors="replace").strip()[-500:]
                    raise SolverError(where, name, f"gcc failed: {message}")
    finally:
        for process, _ in running:
            process.kill()
            process.wait()


def _compile(sources: list[str], name: str, flags: Sequence[str], tmp: Path, library: Path) -> None:
    """gcc: one shared library from ``sources``. Several files: each compiled to an object by up to
    :func:`compile_jobs` processes side by side (largest first), then linked."""
    c_files = [tmp / f"{name}_{k}.c" for k in range(len(sources))]
    for c_file, source in zip(c_files, sources, strict=True):
        c_file.write_text(source)
    if len(c_files) == 1:
        _run_side_by_side([["gcc", "-shared", "-fPIC", *flags, str(c_files[0]), "-o", str(library), "-lm"]], 1,
                          str(c_files[0]), name, tmp)
        return
    order = sorted(range(len(sources)), key=lambda k: -len(sources[k]))
    objects = [c.with_suffix(".o") for c in c_files]
    compile_flags = [f for f in flags if f != "-shared"]
    _run_side_by_side([["gcc", "-c", "-fPIC", *compile_flags, str(c_files[k]), "-o", str(objects[k])]
                       for k in order], compile_jobs(), str(c_files[0]), name, tmp)
    _run_side_by_side([["gcc", "-shared", "-fPIC", *flags, *map(str, objects), "-o", str(library), "-lm"]], 1,
                      str(c_files[0]), name, tmp)


def _library_path(name: str, functions: Sequence[ca.Function] | Callable[[], Sequence[ca.Function]], subdir: str,
                  flags: Sequence[str], key: str | None, cache_dir: Path | None) -> tuple[Path, list[str] | None]:
    """Where the library of ``functions`` is cached, and their C code when the key needed it."""
    cache = _writable_cache((cache_dir if cache_dir is not None else cache_root()) / subdir)
    sources = None
    if key is None:
        sources = _sources(functions() if callable(functions) else functions, name)
        key = _key_of(sources, flags)
    return cache / f"{name}_{key}.so", sources


def library_key(functions: Sequence[ca.Function], name: str, flags: Sequence[str] = DEFAULT_FLAGS) -> str:
    """The key :func:`build_library` names the library of ``functions`` by (SHA-256 of their code)."""
    return _key_of(_sources(functions, name), flags)


def _key_of(sources: list[str], flags: Sequence[str]) -> str:
    return hashlib.sha256(("".join(sources) + " ".join(flags) + ca.__version__).encode()).hexdigest()[:20]


def cached_library(name: str, key: str, *, subdir: str = "casadi", cache_dir: Path | None = None) -> Path | None:
    """The intact cached library ``name`` with ``key`` (:func:`library_key`), else None."""
    library = _writable_cache((cache_dir if cache_dir is not None else cache_root()) / subdir) / f"{name}_{key}.so"
    return library if _intact(library) else None


def build_library(name: str, functions: Sequence[ca.Function] | Callable[[], Sequence[ca.Function]], *,
                  subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS, key: str | None = None,
                  cache_dir: Path | None = None) -> Path:
    """Path of the shared library holding ``functions`` (compiled now if not cached).

    Several functions are compiled in files of their own by up to :func:`compile_jobs` gcc
    processes side by side (the PtP NLP of a 6-axis arm: its Lagrangian Hessian is most of the
    code, so two cores take the time of the Hessian alone); the key does not depend on the cores."""
    library, sources = _library_path(name, functions, subdir, flags, key, cache_dir)
    if _intact(library):
        return library
    with _build_lock(library, name):      # another process building it: wait for its library
        if _intact(library):
            return library
        with progress.task(f"compiling {name} (C code, gcc)"):
            if sources is None:
                sources = _sources(functions() if callable(functions) else functions, name)
            _build(sources, name, flags, library)
    return library


@contextlib.contextmanager
def _build_lock(library: Path, name: str | None = None) -> Iterator[None]:
    """An exclusive ``flock`` on ``.<library>.lock`` beside the library while it is built, so that two
    processes (a run's background warm-up, :mod:`pipeline.run.warm_up`, and its stage) never compile the
    same library side by side: the second waits (a progress line says for what) and finds it built.
    No lock (a folder that refuses the file) only costs a possible second build."""
    try:
        handle = open(library.with_name(f".{library.name}.lock"), "a")  # noqa: SIM115 (held across the yield)
    except OSError:
        yield
        return
    with handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:     # another process compiles it (e.g. the run's background warm-up)
            what = library.name if name is None else name
            with progress.task(f"compiling {what} (C code, gcc; in another process, waiting for it)"):
                fcntl.flock(handle, fcntl.LOCK_EX)
        yield


def _build(sources: list[str], name: str, flags: Sequence[str], library: Path) -> None:
    """Compile ``sources`` into ``library``: in a temporary folder beside it, then renamed into place."""
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        tmp_library = Path(tmp) / library.name
        _compile(sources, name, flags, Path(tmp), tmp_library)
        stamp = Path(tmp) / (library.name + ".sha256")
        stamp.write_text(_sha256(tmp_library) + "\n")
        os.replace(tmp_library, library)
        os.replace(stamp, library.with_name(library.name + ".sha256"))


def compile_function(function: ca.Function, *, subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS,
                     cache_dir: Path | None = None) -> ca.Function:
    """``function`` compiled and loaded with ``ca.external`` (same inputs and outputs; evaluate it
    numerically or in MX graphs, not with SX arguments)."""
    library = build_library(function.name(), [function], subdir=subdir, flags=flags, cache_dir=cache_dir)
    return ca.external(function.name(), str(library))
