"""The knobs of ``mipray-sweep``: which render settings a sweep varies, and their values.

:data:`KNOBS` lists each knob and the values it takes; :func:`parse_knob` reads
``NAME=V1,V2,...``; :func:`plan_rows` turns knobs into the settings of each
row; :func:`auto_reference_settings` is the ``auto`` reference. Knobs the
renderer does not have yet (:data:`RESERVED_KNOBS`, and :data:`OPTIONAL_KNOBS`
in a build without their setting) are refused with a message
saying so. Every error is a one-line :class:`SweepError` that lists the valid
knobs and their ranges.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from ..errors import MiprayError, RenderSettingsError
from ..settings import TABLE
from ..settings import parse as parse_setting

__all__ = [
    "DEFAULT_REFERENCE_SAMPLES",
    "KNOBS",
    "OPTIONAL_KNOBS",
    "REFERENCE_TESS_FACTOR",
    "RESERVED_KNOBS",
    "Knob",
    "SweepError",
    "auto_reference_settings",
    "available_knobs",
    "check_base",
    "check_knobs",
    "parse_knob",
    "plan_rows",
    "unavailable_knobs",
]

#: Camera samples of the ``auto`` reference (at least; more if a row asks for more).
DEFAULT_REFERENCE_SAMPLES = 64
#: The tess factor of the ``auto`` reference (quads a quarter of a beam width).
REFERENCE_TESS_FACTOR = 0.25


class SweepError(MiprayError):
    """A sweep that cannot start or cannot go on; the message is one line."""


@dataclass(frozen=True)
class Knob:
    """A render setting a sweep can vary: its row of the settings table."""

    #: The render setting's name (a key of :data:`mipray.settings.TABLE`).
    name: str
    #: ``"float"``, ``"int"``, ``"bool"`` or ``"choice"``.
    kind: str
    #: What it changes, for ``--list-knobs``.
    help: str
    #: The values it takes, in words (``"integer, 0 ≤ x ≤ 64"``).
    range: str
    choices: tuple[str, ...] = ()

    def describe(self) -> str:
        """The values it takes, e.g. ``'number, 0 < x ≤ 10'``."""
        return self.range

    def parse(self, value: object) -> object:
        """``value`` (text, or a number from Python) as this knob's type.

        Raises:
            SweepError: the value is not one this knob takes; the message lists
                every knob and its range.

        """
        try:
            return parse_setting(self.name, value.strip() if isinstance(value, str) else value)
        except RenderSettingsError as exc:
            raise SweepError(f"{exc}. Valid knobs: {_valid_knobs()}") from exc


def _knobs(names: Sequence[str]) -> dict[str, Knob]:
    rows = [TABLE[n] for n in names if n in TABLE]
    return {
        r["key"]: Knob(r["key"], r["type"], r["help"], r["range"], tuple(r["choices"]))
        for r in rows
    }


#: The knobs a sweep varies, by render-setting name: what a setting takes is the
#: settings table's (:mod:`mipray.settings`); which settings are knobs is the sweep's.
KNOBS: dict[str, Knob] = _knobs(
    (
        "tessFactor",
        "tessFactorIncoherent",
        "geometryCacheMb",
        "geometryCacheCoarseMb",
        "geometryCacheMediumMb",
        "geometryCacheFineMb",
        "cacheMode",
        "samples",
        "aoSamples",
        "maxDepth",
    )
)

#: Knobs for settings that newer builds of the renderer have: offered when
#: ``mipray._mipray.render_settings()`` lists the setting, refused otherwise.
OPTIONAL_KNOBS: dict[str, Knob] = _knobs(
    ("textureFilter", "textureCacheMb", "shadowSamples", "irradianceCache", "irradianceCacheError")
)

#: Knobs the renderer does not have yet: refused with a message saying so (none at present).
RESERVED_KNOBS: dict[str, str] = {}


@functools.cache
def _renderer_settings() -> tuple[str, ...]:
    """The settings the compiled renderer takes (empty without it)."""
    try:
        from .. import _mipray
    except ImportError:
        return ()
    # Not in the hand-written stubs yet: asked for by name, so an older build still works.
    listing = getattr(_mipray, "render_settings", None)
    return tuple(str(s[0]) for s in listing()) if callable(listing) else ()


def available_knobs() -> dict[str, Knob]:
    """The knobs this build can sweep: :data:`KNOBS` and the optional ones it has."""
    have = _renderer_settings()
    return {**KNOBS, **{k: v for k, v in OPTIONAL_KNOBS.items() if k in have}}


def unavailable_knobs() -> dict[str, str]:
    """Knob name → what it would vary, for knobs this build refuses."""
    have = _renderer_settings()
    missing = {k: v.help for k, v in OPTIONAL_KNOBS.items() if k not in have}
    return {**missing, **RESERVED_KNOBS}


def _valid_knobs() -> str:
    return "; ".join(f"{k.name} ({k.describe()})" for k in available_knobs().values())


def _check_knob_name(name: str) -> Knob:
    knobs = available_knobs()
    if name in knobs:
        return knobs[name]
    refused = unavailable_knobs()
    if name in refused:
        raise SweepError(
            f"knob '{name}' ({refused[name]}) is not yet available in this build of mipray. "
            f"Valid knobs: {_valid_knobs()}"
        )
    raise SweepError(f"unknown knob '{name}'. Valid knobs: {_valid_knobs()}")


def parse_knob(spec: str) -> tuple[str, list[object]]:
    """``'tessFactor=0.25,0.5'`` → ``('tessFactor', [0.25, 0.5])``, checked.

    Raises:
        SweepError: no ``=``, an unknown or reserved knob, or a value the knob
            does not take; the message lists the valid knobs and ranges.

    """
    name, sep, values = spec.partition("=")
    name = name.strip()
    if not sep or not name:
        raise SweepError(f"--knob '{spec}' is not NAME=V1,V2,...; valid knobs: {_valid_knobs()}")
    knob = _check_knob_name(name)
    items = [v for v in (s.strip() for s in values.split(",")) if v]
    if not items:
        raise SweepError(f"--knob {name}= has no values; {name} takes {knob.describe()}")
    return name, list(dict.fromkeys(knob.parse(v) for v in items))


def check_knobs(knobs: Mapping[str, Sequence[object]] | Sequence[str]) -> dict[str, list[object]]:
    """Knobs from Python (a mapping) or the command line (``NAME=V,...`` strings)."""
    checked: dict[str, list[object]] = {}
    if isinstance(knobs, Mapping):
        pairs: list[tuple[str, list[object]]] = []
        for name, values in knobs.items():
            knob = _check_knob_name(str(name))
            seq = [values] if isinstance(values, (str, int, float)) else list(values)
            if not seq:
                raise SweepError(f"knob {name} has no values; it takes {knob.describe()}")
            pairs.append((knob.name, list(dict.fromkeys(knob.parse(v) for v in seq))))
    else:
        pairs = [parse_knob(s) for s in knobs]
    for name, values in pairs:
        if name in checked:
            raise SweepError(f"knob {name} is given twice; give its values once: {name}=a,b,c")
        checked[name] = values
    if not checked:
        raise SweepError(
            f"no knob to sweep; give one, e.g. --knob tessFactor=0.5,1,2. "
            f"Valid knobs: {_valid_knobs()}"
        )
    return checked


def plan_rows(
    knobs: Mapping[str, Sequence[object]], zip_knobs: bool = False
) -> list[dict[str, object]]:
    """The settings of each row, in order.

    The cartesian product of the knobs' values, first knob slowest; or with
    ``zip_knobs`` the i-th value of every knob together (a knob with one value
    goes with all).

    Raises:
        SweepError: ``zip_knobs`` with knobs of different numbers of values.

    """
    names = list(knobs)
    if not zip_knobs:
        return [
            dict(zip(names, combo, strict=True)) for combo in itertools.product(*knobs.values())
        ]
    lengths = {len(v) for v in knobs.values() if len(v) != 1}
    if len(lengths) > 1:
        counts = ", ".join(f"{k} {len(v)}" for k, v in knobs.items())
        raise SweepError(f"--zip needs knobs with the same number of values (or one); got {counts}")
    n = lengths.pop() if lengths else 1
    return [{k: (v[0] if len(v) == 1 else v[i]) for k, v in knobs.items()} for i in range(n)]


def auto_reference_settings(
    knobs: Mapping[str, Sequence[object]],
    base: Mapping[str, object],
    reference_samples: int = DEFAULT_REFERENCE_SAMPLES,
) -> dict[str, object]:
    """The most accurate settings of a sweep: its ``auto`` reference.

    Tess factor 0.25 (or the finest swept, if finer) with incoherent rays no
    coarser (``tessFactorIncoherent`` at most 1); the unbounded cache (the
    cache never changes pixels, but this is the fastest exact one); at least
    ``reference_samples`` camera samples; the most AO samples and bounces
    swept or set; no irradiance caching when it is swept or set (every
    hemisphere integral sampled); the seed after the rows' so its noise is
    independent.
    """

    def values(name: str) -> list[float]:
        out = [float(v) for v in knobs.get(name, ())]  # type: ignore[arg-type]
        if name in base:
            out.append(float(base[name]))  # type: ignore[arg-type]
        return out

    ref: dict[str, object] = {
        k: v
        for k, v in base.items()
        if not k.startswith("geometryCache") and k not in ("cacheMode", "textureCacheMb")
    }
    ref["tessFactor"] = min([REFERENCE_TESS_FACTOR, *values("tessFactor")])
    ref["tessFactorIncoherent"] = min([1.0, *values("tessFactorIncoherent")])
    ref["cacheMode"] = "unbounded"
    ref["samples"] = int(max([reference_samples, *values("samples")]))
    for name in ("aoSamples", "shadowSamples", "maxDepth"):
        if values(name):
            ref[name] = int(max(values(name)))
    # Every hemisphere integral sampled, none interpolated: the irradiance cache off.
    if values("irradianceCache") or values("irradianceCacheError"):
        ref["irradianceCache"] = 0
        ref.pop("irradianceCacheError", None)
    ref["seed"] = int(float(base.get("seed", 0))) + 1  # type: ignore[arg-type]
    return ref


def check_base(settings: Mapping[str, object] | Sequence[str] | None) -> dict[str, object]:
    """Fixed settings (``--set KEY=VALUE`` or a mapping), checked against the renderer's."""
    base: dict[str, object] = {}
    if settings is None:
        return base
    if isinstance(settings, Mapping):
        base = dict(settings)
    else:
        for spec in settings:
            name, sep, text = spec.partition("=")
            if not sep or not name.strip():
                raise SweepError(f"--set '{spec}' is not KEY=VALUE")
            base[name.strip()] = _setting_value(text.strip())
    known = _renderer_settings()
    for key, given in list(base.items()):
        if key in unavailable_knobs():
            _check_knob_name(key)
        if known and key not in known:
            raise SweepError(f"unknown render setting '{key}'; settings: {', '.join(known)}")
        knob = available_knobs().get(key)
        if knob is not None:
            base[key] = knob.parse(given)
    return base


def _setting_value(text: str) -> object:
    """A fixed setting's value as typed: a number where it reads as one, else text.

    Its range is the renderer's to check, in the run that uses it.
    """
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text
