"""The loss of a fit as data: its term names, their kinds and aliases, and :class:`Loss`, a
weighted sum of named terms with its text form (``"p2s+0.001*chamfer"``). numpy only: the
configuration (:mod:`nurbs_core.fitting.config`) and the loss functions (:mod:`nurbs_core.losses`)
both stand on it.
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

#: Loss term name -> kind. ``pointwise`` terms pair points (foot points for unordered clouds),
#: ``set`` terms compare point sets, ``regulariser`` terms look at the geometry alone. The
#: functions live in :mod:`nurbs_core.losses` (which checks it implements exactly these).
LOSS_TERMS: dict[str, str] = {
    "p2s": "pointwise", "chamfer": "set", "hausdorff": "set", "laplacian": "regulariser",
    "fairing": "regulariser", "length": "regulariser", "l1": "pointwise", "l2": "pointwise",
    "mse": "pointwise",
}
LOSS_ALIASES = {"cd": "chamfer", "hd": "hausdorff", "lap": "laplacian", "curve_length": "length",
                "point_to_surface": "p2s", "thin_plate": "fairing"}
_TERM = re.compile(r"^\s*(?:(?P<weight>[0-9]*\.?[0-9]+(?:[eE][-+]?[0-9]+)?)\s*\*\s*)?"
                   r"(?P<name>[A-Za-z_][A-Za-z0-9_]*)\s*$")


@dataclass(frozen=True)
class Loss:
    """A weighted sum of named loss terms: ``terms`` ((name, weight), ...), names from
    :data:`LOSS_TERMS`, each at most once, weights finite and non-negative.

    ``Loss.parse("chamfer+0.1*laplacian+10*hausdorff")`` reads the text form (aliases such as
    ``cd``, ``hd``, ``lap`` allowed; a repeated term has its weights added) and ``str(loss)`` writes
    it back (positional numbers, so ``1e+06`` never appears); ``Loss.of`` accepts either form."""

    terms: tuple[tuple[str, float], ...]

    def __post_init__(self) -> None:
        terms = tuple((str(name), float(weight)) for name, weight in self.terms)
        if not terms:
            raise ValueError("a loss needs at least one term; try 'chamfer+0.1*laplacian'")
        names = [name for name, _ in terms]
        for name, weight in terms:
            if name not in LOSS_TERMS:
                raise ValueError(f"unknown loss term {name!r}; known: {', '.join(LOSS_TERMS)}")
            if not (np.isfinite(weight) and weight >= 0):
                raise ValueError(f"the weight of {name} must be a finite non-negative number, "
                                 f"got {weight!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"a loss names each term once, got {', '.join(names)}")
        object.__setattr__(self, "terms", terms)

    @classmethod
    def parse(cls, text: str) -> Loss:
        """The text form: terms joined by ``+``, each ``[weight*]name``. Raises ValueError naming
        the offending part."""
        if not isinstance(text, str) or not text.strip():
            raise ValueError("the loss expression is empty; try 'chamfer+0.1*laplacian+10*hausdorff'")
        weights: dict[str, float] = {}
        for part in text.split("+"):
            match = _TERM.match(part)
            if match is None:
                raise ValueError(f"cannot parse loss term {part.strip()!r} in {text!r}: expected "
                                 "'name' or 'weight*name', e.g. '0.1*laplacian'")
            name = match.group("name").lower()
            name = LOSS_ALIASES.get(name, name)
            if name not in LOSS_TERMS:
                raise ValueError(f"unknown loss term {match.group('name')!r} in {text!r}; known: "
                                 f"{', '.join(sorted(LOSS_TERMS))}")
            weights[name] = weights.get(name, 0.0) + float(match.group("weight") or 1.0)
        return cls(tuple(weights.items()))

    @classmethod
    def of(cls, value: Loss | str | Iterable[tuple[str, float]]) -> Loss:
        """A Loss from a Loss, its text form, or (name, weight) pairs."""
        if isinstance(value, Loss):
            return value
        if isinstance(value, str):
            return cls.parse(value)
        return cls(tuple(value))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(name for name, _ in self.terms)

    def weight(self, name: str) -> float:
        """The weight of ``name`` (0 when the loss has no such term)."""
        return dict(self.terms).get(name, 0.0)

    def kinds(self) -> set[str]:
        return {LOSS_TERMS[name] for name in self.names}

    def __str__(self) -> str:
        return "+".join(name if weight == 1.0
                        else f"{np.format_float_positional(weight, trim='-')}*{name}"
                        for name, weight in self.terms)
