"""Names derived from outside text (a URDF's ``<robot name>``, a link or joint name) made into
identifiers that CasADi, C code generation and file names accept.

CasADi accepts a function or solver name only if it starts with a letter, holds only letters,
digits and ``_``, and has no ``__`` (reserved). A URDF's ``<robot name="gen3_">`` would give the
solver name ``ptp_gen3__25``: every name that carries outside text goes through
:func:`casadi_identifier`.
"""

from __future__ import annotations

import re

_NOT_WORD = re.compile(r"[^A-Za-z0-9]+")


def casadi_identifier(*parts: object, fallback: str = "f") -> str:
    """``parts`` joined by ``_`` as a CasADi-legal identifier: every run of characters other than
    ASCII letters and digits becomes one ``_``, none leads or trails, and a name that would not start
    with a letter is prefixed with ``fallback`` (itself a legal name)."""
    words = [w for part in parts for w in _NOT_WORD.split(str(part)) if w]
    name = "_".join(words)
    if not name or not name[0].isalpha():
        name = f"{fallback}_{name}" if name else fallback
    return name
