"""What a binding can drive: a channel, a `_l`/`_r` pair as one, a FACS AU, an expression preset.
A target resolves to weighted contributions to face channels, so everything downstream works on
one flat array of channel values."""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from puppet.errors import ChannelError
from safefile import few, quote


@dataclass(frozen=True)
class ChannelInfo:
    """The part of sim's ChannelSpec the mapping needs."""

    name: str
    kind: str
    lo: float
    hi: float
    default: float


@dataclass(frozen=True)
class Target:
    """A resolved target. `direct`: the binding's value is in channel units and goes to every
    channel listed (weights 1); otherwise the value is a 0..1 weight and channel i receives
    weight * w_i. `lo`/`hi` are the target's natural range (what `to` defaults to)."""

    name: str
    direct: bool
    channels: tuple[tuple[int, float], ...]
    lo: float
    hi: float
    default: float


class Vocabulary:
    """Channel list plus the FACS tables (AU -> {channel: weight}, expression -> {AU: intensity})."""

    def __init__(self, channels: Sequence[ChannelInfo], aus: Mapping[str, Mapping[str, float]] | None = None,
                 expressions: Mapping[str, Mapping[str, float]] | None = None) -> None:
        self.channels = tuple(channels)
        self.index = {c.name: i for i, c in enumerate(self.channels)}
        self.aus = {k.upper(): dict(v) for k, v in (aus or {}).items()}
        self.expressions = {k.lower(): dict(v) for k, v in (expressions or {}).items()}

    @classmethod
    def from_model(cls, model: object) -> Vocabulary:
        """Build from a compiled sim FaceModel and sim.facs (if present)."""
        chans = [ChannelInfo(c.name, c.kind, float(c.lo), float(c.hi), float(c.default))
                 for c in model.channels]  # type: ignore[attr-defined]
        aus: dict = {}
        exprs: dict = {}
        try:
            from sim import facs
            aus = dict(getattr(facs, "AU_TABLE", {}))
            exprs = dict(facs.expressions_for(facs.preset_face(getattr(model, "rig", None))))
        except ImportError:
            pass
        return cls(chans, aus, exprs)

    def defaults(self) -> list[float]:
        return [c.default for c in self.channels]

    def au_weights(self, au: str) -> dict[int, float]:
        table = self.aus.get(au.upper())
        if table is None:
            known = sorted(self.aus, key=_au_key)
            raise ChannelError(f"unknown AU {quote(au)}; known: {few(known)}")
        return {self.index[ch]: float(w) for ch, w in table.items() if ch in self.index}

    def resolve(self, name: str) -> Target:
        """Resolve a target name; unknown names raise ChannelError listing what exists."""
        if name in self.index:
            c = self.channels[self.index[name]]
            return Target(name, True, ((self.index[name], 1.0),), c.lo, c.hi, c.default)
        pair = [f"{name}_l", f"{name}_r"]
        if all(p in self.index for p in pair):
            c = self.channels[self.index[pair[0]]]
            return Target(name, True, tuple((self.index[p], 1.0) for p in pair), c.lo, c.hi, c.default)
        if re.fullmatch(r"[Aa][Uu]\d+(_[LRlr])?", name):
            w = self.au_weights(name)
            return Target(name.upper(), False, tuple(sorted(w.items())), 0.0, 1.0, 0.0)
        if name.lower().startswith("expr:"):
            ex = name[5:].lower()
            table = self.expressions.get(ex)
            if table is None:
                raise ChannelError(f"unknown expression {quote(ex)}; known: {few(sorted(self.expressions))}")
            acc: dict[int, float] = {}
            for au, intensity in table.items():
                for i, w in self.au_weights(au).items():
                    # sim.facs combines an expression's AUs by max per channel; so do we
                    acc[i] = max(acc.get(i, 0.0), float(intensity) * w)
            return Target(f"expr:{ex}", False, tuple(sorted(acc.items())), 0.0, 1.0, 0.0)
        raise ChannelError(self.unknown_message(name))

    def unknown_message(self, name: str) -> str:
        pairs = sorted({c.name[:-2] for c in self.channels if c.name.endswith(("_l", "_r"))} - set(self.index))
        names = [c.name for c in self.channels if not c.name.endswith(("_l", "_r"))] + pairs
        close = [n for n in names if name.lower()[:4] in n.lower()][:6]
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        return (f"unknown target {quote(name)}{hint}; expected a channel ({few(names)}; `puppet channels` "
                f"lists them), a pair's _l/_r channel, an AU like AU12, or expr:<name>")

    def all_targets(self) -> list[str]:
        """Every target name a user can pick in learn mode, channels first."""
        pairs = sorted({c.name[:-2] for c in self.channels if c.name.endswith("_l")
                        and c.name[:-2] + "_r" in self.index} - set(self.index))  # a whole channel's name is the channel
        out = pairs + [c.name for c in self.channels]
        out += sorted(self.aus, key=_au_key)
        out += [f"expr:{e}" for e in sorted(self.expressions)]
        return out


def _au_key(au: str) -> tuple[int, str]:
    m = re.search(r"\d+", au)
    return (int(m.group()) if m else 0, au)
