"""CasADi functions compiled to C with gcc, cached on disk (one place for the whole package).

``build_library`` writes the C code of CasADi functions, compiles it to a shared library and
keeps it under ``$PIPELINE_CACHE_DIR`` (default ``~/.cache/pipeline``)/<subdir>, named by a
key: by default the SHA-256 of the generated code, the gcc flags and the CasADi version, so
any change of the model or expression compiles anew and nothing is compiled twice. Callers
whose code generation is itself costly pass their own ``key`` and a lazy ``functions``
callable: the code is then generated only when the library is missing. Concurrent builders
write the same file atomically (``os.replace``).
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path

import casadi as ca

from pipeline.errors import SolverError

DEFAULT_FLAGS = ("-O2",)


def cache_root() -> Path:
    """``$PIPELINE_CACHE_DIR`` or ``~/.cache/pipeline``."""
    env = os.environ.get("PIPELINE_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "pipeline"


def _generate(functions: Sequence[ca.Function], name: str) -> str:
    generator = ca.CodeGenerator(f"{name}.c", {"with_header": False})
    for function in functions:
        generator.add(function)
    return generator.dump()


def build_library(name: str, functions: Sequence[ca.Function] | Callable[[], Sequence[ca.Function]], *,
                  subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS, key: str | None = None,
                  cache_dir: Path | None = None) -> Path:
    """Path of the shared library holding ``functions`` (compiled now if not cached)."""
    cache = (cache_dir if cache_dir is not None else cache_root()) / subdir
    cache.mkdir(parents=True, exist_ok=True)
    source = None
    if key is None:
        source = _generate(functions() if callable(functions) else functions, name)
        key = hashlib.sha256((source + " ".join(flags) + ca.__version__).encode()).hexdigest()[:20]
    library = cache / f"{name}_{key}.so"
    if library.exists():
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
        os.replace(tmp_library, library)
    return library


def compile_function(function: ca.Function, *, subdir: str = "casadi", flags: Sequence[str] = DEFAULT_FLAGS,
                     cache_dir: Path | None = None) -> ca.Function:
    """``function`` compiled and loaded with ``ca.external`` (same inputs and outputs; evaluate it
    numerically or in MX graphs, not with SX arguments)."""
    library = build_library(function.name(), [function], subdir=subdir, flags=flags, cache_dir=cache_dir)
    return ca.external(function.name(), str(library))
