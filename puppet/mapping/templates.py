"""Template bindings: one `[[binding]]` that stands for a whole family of controls, expanded
against the face's vocabulary when a map is applied. A control and target may contain one of

- `{channel}`: every channel and every `_l`/`_r` pair (`/face/channel/{channel}` -> `{channel}`);
  without `from`, the control's value is read in the channel's own units (its lo..hi);
- `{au}`: every FACS AU the face knows, without the `AU` prefix (`/face/au/{au}` -> `AU{au}`);
- `{expression}`: every expression preset (`/face/expression/{expression}` -> `expr:{expression}`).

So an OSC sender can address anything a face has without a map listing it, and a face with
other channels gets its own addresses."""

from __future__ import annotations

from dataclasses import replace

from puppet.errors import ChannelError
from puppet.mapping.config import BindingSpec, MappingSpec
from puppet.mapping.targets import Vocabulary

PLACEHOLDERS = ("{channel}", "{au}", "{expression}")


def is_template(b: BindingSpec) -> bool:
    return any(p in b.control for p in PLACEHOLDERS)


def _names(placeholder: str, vocab: Vocabulary) -> list[str]:
    if placeholder == "{channel}":
        names = [c.name for c in vocab.channels]
        pairs = sorted({n[:-2] for n in names if n.endswith("_l") and n[:-2] + "_r" in vocab.index})
        return names + pairs
    if placeholder == "{au}":
        return [au[2:] for au in vocab.aus]
    return sorted(vocab.expressions)


def expand(b: BindingSpec, vocab: Vocabulary) -> list[BindingSpec]:
    """The concrete bindings one template stands for (a plain binding is returned as is)."""
    ph = next((p for p in PLACEHOLDERS if p in b.control), None)
    if ph is None:
        return [b]
    out = []
    for name in _names(ph, vocab):
        target = b.target.replace(ph, name) if b.target is not None else None
        src = b.src_range
        if src is None and ph == "{channel}" and target is not None:
            try:
                t = vocab.resolve(target)
                src = (t.lo, t.hi)
            except ChannelError:
                pass  # the mapper reports the bad target at its line in the file
        out.append(replace(b, control=b.control.replace(ph, name), target=target, src_range=src))
    return out


def expand_spec(spec: MappingSpec, vocab: Vocabulary) -> MappingSpec:
    """The map with its templates expanded (the same object when it has none)."""
    if not any(is_template(b) for b in spec.bindings):
        return spec
    bindings = [x for b in spec.bindings for x in expand(b, vocab)]
    return replace(spec, bindings=bindings)
