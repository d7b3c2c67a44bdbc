"""The identity a UAS broadcasts (F3411 Basic ID, Operator ID, System classification):
validation with one clear error each, pure.

- UAS serial number, ANSI/CTA-2063-A: a 4-character manufacturer code, one length character
  (1-9, A-F = 1..15) and the manufacturer's serial of exactly that length; characters 0-9 and
  A-Z without O and I (they read as 0 and 1). At most 20 characters (the Basic ID field).
- Operator ID: the registration number of the operator (EU: 3-letter country code, 12
  characters and a check character, e.g. ``FIN87astrdge12k8``; the 3 secret characters are not
  broadcast): 1-20 printable ASCII characters without spaces. The check character needs the
  secret part and cannot be verified here.
- Classification (EU, prEN 4709-002): ``CATEGORY`` or ``CATEGORY/CLASS`` with category one of
  undeclared, open, specific, certified and class one of undeclared, C0..C6.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from adapters.remoteid.f3411 import EuCategory, EuClass

_CTA_CHARS = "0123456789ABCDEFGHJKLMNPQRSTUVWXYZ"  # no I, no O
_CTA_LENGTHS = "123456789ABCDEF"  # length code -> 1..15
_OPERATOR_ID_RE = re.compile(r"^[\x21-\x7e]{1,20}$")
_CATEGORIES = {c.name.lower(): c for c in EuCategory}
_CLASSES = {"undeclared": EuClass.UNDECLARED} | {f"c{i}": EuClass[f"CLASS_{i}"] for i in range(7)}


class IdentityError(ValueError):
    """A Remote ID identity value that is not valid. ``what`` names the value."""

    def __init__(self, what: str, value: str, reason: str) -> None:
        super().__init__(f"{what} {value!r}: {reason}")
        self.what = what
        self.value = value
        self.reason = reason


def check_serial_number(serial: str) -> str:
    """``serial`` if it is an ANSI/CTA-2063-A serial number, else :class:`IdentityError`."""
    what = "UAS serial number (ANSI/CTA-2063-A)"
    if not 6 <= len(serial) <= 20:
        raise IdentityError(what, serial, f"{len(serial)} characters, expected 6..20")
    bad = sorted({c for c in serial if c not in _CTA_CHARS})
    if bad:
        raise IdentityError(
            what, serial, f"characters {''.join(bad)!r} not allowed (0-9, A-Z without I and O)"
        )
    code = serial[4]
    if code not in _CTA_LENGTHS:
        raise IdentityError(what, serial, f"length code {code!r} is not 1-9 or A-F")
    expected = _CTA_LENGTHS.index(code) + 1
    if len(serial) - 5 != expected:
        raise IdentityError(
            what,
            serial,
            f"length code {code!r} says {expected} serial characters after the "
            f"manufacturer code {serial[:4]!r}, got {len(serial) - 5}",
        )
    return serial


def check_operator_id(operator_id: str) -> str:
    """``operator_id`` if it fits the Operator ID message, else :class:`IdentityError`."""
    if not _OPERATOR_ID_RE.match(operator_id):
        raise IdentityError(
            "operator ID", operator_id, "expected 1..20 printable ASCII characters, no spaces"
        )
    return operator_id


@dataclass(frozen=True, slots=True)
class Classification:
    category: EuCategory
    eu_class: EuClass


def parse_classification(text: str) -> Classification:
    """``open``, ``specific``, ``open/C1`` ... -> :class:`Classification`."""
    category_text, _, class_text = text.strip().lower().partition("/")
    category = _CATEGORIES.get(category_text)
    if category is None:
        raise IdentityError(
            "classification", text, f"category must be one of {', '.join(_CATEGORIES)}"
        )
    eu_class = _CLASSES.get(class_text or "undeclared")
    if eu_class is None:
        raise IdentityError("classification", text, "class must be undeclared or C0..C6")
    return Classification(category, eu_class)
