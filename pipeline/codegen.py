"""CasADi functions compiled to C with gcc, cached on disk (one place for the whole package).

``build_library`` writes the C code of CasADi functions, compiles it to a shared library and
keeps it under ``$PIPELINE_CACHE_DIR`` (default ``$XDG_CACHE_HOME/pipeline``, else
``~/.cache/pipeline``)/<subdir>, named by a
key: by default the SHA-256 of the generated code, the gcc flags and the CasADi version, so
any change of the model or expression compiles anew and nothing is compiled twice. Callers
whose code generation is itself costly pass their own ``key`` and a lazy ``functions``
callable: the code is then generated only when the library is missing. Concurrent builders
write the same file atomically (``os.replace``).

Faults: a cache folder that cannot be written falls back to a private temporary cache (with a
warning on stderr); every library has its SHA-256 in ``<library>.sha256`` beside it and is
verified before it is loaded (``dlopen`` of a truncated library crashes the process with
SIGBUS): a library that does not match is compiled again.
"""

from __future__ import annotations

import errno
import hashlib
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import casadi as ca

from pipeline.errors import SolverError

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


def build_library(name: str, functions: Sequence[ca.Function] | Callable[[], Sequence[ca.Function]], *,
                  subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS, key: str | None = None,
                  cache_dir: Path | None = None) -> Path:
    """Path of the shared library holding ``functions`` (compiled now if not cached)."""
    cache = _writable_cache((cache_dir if cache_dir is not None else cache_root()) / subdir)
    source = None
    if key is None:
        source = _generate(functions() if callable(functions) else functions, name)
        key = hashlib.sha256((source + " ".join(flags) + ca.__version__).encode()).hexdigest()[:20]
    library = cache / f"{name}_{key}.so"
    if _intact(library):
        return library
    if source is None:
        source = _generate(functions() if callable(functions) else functions, name)
    with tempfile.TemporaryDirectory(dir=cache) as tmp:
        c_file = Path(tmp) / f"{name}.c"
        c_file.write_text(source)
        tmp_library = Path(tmp) / library.name
        command = ["gcc", "-shared", "-fPIC", *flags, str(c_file), "-o", str(tmp_library), "-lm"]
        result = subprocess.run(command, capture_output=True, text=True, check=False)
        if result.returncode != 0:
            raise SolverError(str(c_file), name, f"gcc failed: {result.stderr.strip()[-500:]}")
        stamp = Path(tmp) / (library.name + ".sha256")
        stamp.write_text(_sha256(tmp_library) + "\n")
        os.replace(tmp_library, library)
        os.replace(stamp, library.with_name(library.name + ".sha256"))
    return library


def compile_function(function: ca.Function, *, subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS,
                     cache_dir: Path | None = None) -> ca.Function:
    """``function`` compiled and loaded with ``ca.external`` (same inputs and outputs; evaluate it
    numerically or in MX graphs, not with SX arguments)."""
    library = build_library(function.name(), [function], subdir=subdir, flags=flags, cache_dir=cache_dir)
    return ca.external(function.name(), str(library))
