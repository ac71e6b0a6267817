"""The argument types of every ``jamflow`` option: each number and output path is checked as it is parsed.

A value outside its type is a usage error (exit code 2, one line naming the option and
what it must be), before any file is read. Every numeric option of every command uses
one of these types (``tests/test_cli_types.py`` walks the parsers and fails on any that
does not): ``float`` and ``int`` accept ``nan``, ``inf`` and negative counts, which then
run until killed or give numbers from nonsense.

Real numbers: :func:`finite`, :func:`positive`, :func:`non_negative`,
:func:`probability` ([0, 1]), :func:`packing_fraction` ((0, 1)), or any interval from
:func:`real`. Integers: :func:`count` (>= 1), :func:`non_negative_int`, :func:`seed`
([0, 2**64)), :func:`bins`, :func:`resamples`, or any range from :func:`integer`. Output
paths: :func:`path_with_suffix`.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

__all__ = ["ArgumentType", "MAX_BINS", "MAX_RESAMPLES", "UsageError", "bins", "count", "finite", "integer", "is_argument_type", "non_negative", "non_negative_int",
           "packing_fraction", "path_with_suffix", "positive", "probability", "real", "require_suffix", "resamples",
           "seed"]

#: Seeds are unsigned 64-bit integers: numpy's generators take any, but the netCDF
#: attribute that records them holds at most an unsigned 64-bit one.
SEED_LIMIT: int = 2**64


class UsageError(ValueError):
    """A command line that cannot be run as given (exit code 2, like argparse's own errors)."""


class ArgumentType:
    """A checked argparse type: ``parse(text)`` or ``argparse.ArgumentTypeError`` saying what it must be.

    Attributes
    ----------
    need : str
        What a value must be, e.g. ``"a positive number"`` (shown in the error).
    """

    def __init__(self, name: str, need: str, parse: Callable[[str], Any], ok: Callable[[Any], bool]) -> None:
        self.__name__ = name  # argparse names the type in some messages
        self.need = need
        self._parse = parse
        self._ok = ok

    def __call__(self, text: str) -> Any:
        try:
            value = self._parse(text)
        except (ValueError, OverflowError):
            raise argparse.ArgumentTypeError(f"must be {self.need}, got {text!r}") from None
        if not self._ok(value):
            raise argparse.ArgumentTypeError(f"must be {self.need}, got {text}")
        return value

    def __repr__(self) -> str:
        return f"<argument type {self.__name__}: {self.need}>"


def is_argument_type(value: Any) -> bool:
    """Whether ``value`` is one of this module's checked types (the parser-walking test asks)."""
    return isinstance(value, ArgumentType)


def _float(text: str) -> float:
    return float(text)


def _int(text: str) -> int:
    # int("1e3") fails; a count written as 1e3 is read exactly when it is an integer
    try:
        return int(text, 10)
    except ValueError:
        value = float(text)
        if not value.is_integer():
            raise
        return int(value)


def _interval(lo: float | None, hi: float | None, lo_open: bool, hi_open: bool) -> str:
    left = "-inf" if lo is None else f"{lo:g}"
    right = "inf" if hi is None else f"{hi:g}"
    return f"{'(' if lo_open or lo is None else '['}{left}, {right}{')' if hi_open or hi is None else ']'}"


def real(lo: float | None = None, hi: float | None = None, *, lo_open: bool = False, hi_open: bool = False,
         need: str | None = None) -> ArgumentType:
    """A finite real number in an interval (closed ends unless ``lo_open`` / ``hi_open``; None: unbounded)."""
    def ok(v: float) -> bool:
        return (math.isfinite(v) and (lo is None or (v > lo if lo_open else v >= lo))
                and (hi is None or (v < hi if hi_open else v <= hi)))

    return ArgumentType("real", need or f"a finite number in {_interval(lo, hi, lo_open, hi_open)}", _float, ok)


def integer(lo: int | None = None, hi: int | None = None, need: str | None = None) -> ArgumentType:
    """An integer in ``[lo, hi]`` (None: unbounded)."""
    def ok(v: int) -> bool:
        return (lo is None or v >= lo) and (hi is None or v <= hi)

    if need is None:
        need = (f"an integer in [{lo}, {hi}]" if lo is not None and hi is not None
                else f"an integer >= {lo}" if lo is not None else f"an integer <= {hi}" if hi is not None
                else "an integer")
    return ArgumentType("integer", need, _int, ok)


#: Any finite real number.
finite = real(need="a finite number")
#: A finite number > 0 (rates, tolerances, pressures, durations, lengths).
positive = real(0.0, lo_open=True, need="a positive finite number")
#: A finite number >= 0.
non_negative = real(0.0, need="a finite number >= 0")
#: A probability or fraction of a whole, in [0, 1].
probability = real(0.0, 1.0, need="a number in [0, 1]")
#: A packing fraction, in (0, 1).
packing_fraction = real(0.0, 1.0, lo_open=True, hi_open=True, need="a packing fraction in (0, 1)")
#: A number of things, at least one (particles, bins, steps, resamples).
count = integer(1, need="an integer >= 1")
#: A number of things that may be zero (snapshots, an index).
non_negative_int = integer(0, need="an integer >= 0")
#: A random seed: an integer in [0, 2**64).
seed = integer(0, SEED_LIMIT - 1, need="an integer in [0, 2**64)")

#: Most bins of a histogram (or blocks of a block average): more than there are particles in
#: any packing jamflow makes leaves almost every bin empty, and 10**12 would not fit in memory.
MAX_BINS: int = 10**6
#: Most bootstrap resamples: the relative error of a bootstrap standard error is about
#: 1 / sqrt(2 n), 0.2 % at 10**5; more only costs time.
MAX_RESAMPLES: int = 10**5

#: A number of histogram bins.
bins = integer(1, MAX_BINS, need=f"a number of bins in [1, {MAX_BINS}]")
#: A number of bootstrap resamples (a standard error needs two).
resamples = integer(2, MAX_RESAMPLES, need=f"a number of resamples in [2, {MAX_RESAMPLES}]")


def require_suffix(path: str, suffixes: tuple[str, ...]) -> str:
    """``path`` if it ends in one of ``suffixes`` (case-insensitive), else a ``ValueError`` in one line."""
    if not any(str(path).lower().endswith(s.lower()) for s in suffixes):
        raise ValueError(f"{path}: must end in {' or '.join(suffixes)} (the suffix says what the file holds)")
    return str(path)


def path_with_suffix(*suffixes: str) -> ArgumentType:
    """An output path that must end in one of ``suffixes`` (``.nc`` for netCDF, ``.xyz`` ...)."""
    def parse(text: str) -> str:
        if not text or Path(text).name in ("", ".", ".."):
            raise ValueError(text)
        return text

    def ok(text: str) -> bool:
        return any(text.lower().endswith(s.lower()) for s in suffixes)

    kind = ArgumentType("path", f"a file path ending in {' or '.join(suffixes)}", parse, ok)
    kind.suffixes = suffixes
    return kind
