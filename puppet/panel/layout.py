"""What the page shows and which controls it sends: sliders per channel grouped by face region,
pads for the expression presets and FACS AUs, the age dial, panic and marker buttons; and the
mapping that turns those controls into targets (a map like the shipped ones, generated from the
face so a rig with other channels gets its own sliders)."""

from __future__ import annotations

import fnmatch
import re
from collections.abc import Sequence
from typing import Any

from puppet.mapping import MappingSpec, Vocabulary, parse_mapping

#: face regions, top to bottom, and the channel name prefixes that belong to each
REGIONS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("brows", ("frontalis", "corrugator", "procerus")),
    ("eyes", ("orbicularis_oculi", "levator_palpebrae", "eyes_")),
    ("nose and cheeks", ("levator_labii", "zygomaticus", "levator_anguli", "buccinator", "cheek_")),
    ("mouth", ("orbicularis_oris", "depressor", "mentalis", "risorius", "incisivus", "lip_", "mouth_",
               "tongue", "platysma")),
    ("jaw", ("jaw",)),
    ("head", ("head_",)),
)
PANIC, MARKER = "button:panic", "button:marker"
EXPR_GROUP = "panel_expression"


def region_of(name: str) -> str:
    for region, prefixes in REGIONS:
        if name.startswith(prefixes):
            return region
    return "other"


def _pairs(vocab: Vocabulary) -> list[dict[str, Any]]:
    """One row per channel, `_l/_r` pairs as one row with two sliders."""
    names = [c.name for c in vocab.channels]
    rows: list[dict[str, Any]] = []
    done: set[str] = set()
    for c in vocab.channels:
        if c.name in done or c.kind == "age":
            continue
        base = c.name[:-2]
        if c.name.endswith("_l") and base + "_r" in names:
            chans = [c.name, base + "_r"]
            label = base + " half" if base in names else base  # a whole channel's sided halves (sim.channels.HALVES)
        else:
            chans, label = [c.name], c.name
        done.update(chans)
        rows.append({"label": label, "region": region_of(c.name), "channels": chans,
                     "lo": c.lo, "hi": c.hi, "default": c.default})
    return rows


def build_layout(vocab: Vocabulary) -> dict[str, Any]:
    """The page's layout: channel list (for the applied values), rows grouped by region, pads."""
    rows = _pairs(vocab)
    regions = [r for r, _ in REGIONS] + ["other"]
    age = next((c for c in vocab.channels if c.kind == "age"), None)
    aus = sorted((a for a in vocab.aus if re.fullmatch(r"AU\d+", a)), key=lambda a: int(a[2:]))
    return {
        "channels": [{"name": c.name, "lo": c.lo, "hi": c.hi, "default": c.default} for c in vocab.channels],
        "regions": [{"name": r, "rows": [x for x in rows if x["region"] == r]} for r in regions
                    if any(x["region"] == r for x in rows)],
        "expressions": sorted(vocab.expressions),
        "aus": aus,
        "age": None if age is None else {"name": age.name, "lo": age.lo, "hi": age.hi, "default": age.default},
    }


def panel_map_text(vocab: Vocabulary) -> str:
    """TOML of the page's bindings: `slider:CHANNEL` absolute without pickup (a touched slider
    takes over at once, as a finger expects), `pad:expr:NAME` a radio group, `pad:AUn` held,
    panic and marker buttons."""
    out = ['version = 1', 'name = "browser panel"', 'device = "panel"', "",
           "[groups]", f"{EXPR_GROUP} = {{ allow_none = true }}", ""]

    def binding(**kw: Any) -> None:
        out.append("[[binding]]")
        for k, v in kw.items():
            out.append(f"{k} = {'true' if v is True else 'false' if v is False else repr(v) if isinstance(v, str) else v}"
                       .replace("'", '"'))
        out.append("")

    for c in vocab.channels:
        binding(control=f"slider:{c.name}", target=c.name, input="absolute", pickup=False)
    for e in sorted(vocab.expressions):
        binding(control=f"pad:expr:{e}", target=f"expr:{e}", mode="radio", group=EXPR_GROUP)
    for au in build_layout(vocab)["aus"]:
        binding(control=f"pad:{au}", target=au, mode="momentary", attack=0.06, release=0.12)
    binding(control=PANIC, action="panic", label="page panic")
    binding(control=MARKER, action="marker", label="page marker")
    return "\n".join(out)


def panel_map(vocab: Vocabulary) -> MappingSpec:
    return parse_mapping(panel_map_text(vocab), "<browser panel map>")


def controls_of(vocab: Vocabulary) -> list[str]:
    """Every control name the page may send."""
    lay = build_layout(vocab)
    out = [f"slider:{c.name}" for c in vocab.channels]
    out += [f"pad:expr:{e}" for e in lay["expressions"]] + [f"pad:{a}" for a in lay["aus"]]
    return out + [PANIC, MARKER]


def allowed_controls(vocab: Vocabulary, patterns: Sequence[str] | None) -> set[str]:
    """The controls a client limited to `patterns` (globs over channel, pair, AU or expression
    names) may send. A pad is allowed when its name matches or every channel it drives does.
    Panic is always allowed: anyone may stop the face."""
    every = controls_of(vocab)
    if not patterns:
        return set(every)
    pats = [p.strip() for p in patterns if p.strip()]

    def match(name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, p) for p in pats)

    ok = {PANIC, MARKER}
    for ctl in every:
        if ctl in (PANIC, MARKER):
            continue
        target = ctl.split(":", 1)[1]
        if ctl.startswith("slider:"):
            base = target[:-2] if target.endswith(("_l", "_r")) else target
            if match(target) or match(base):
                ok.add(ctl)
            continue
        chans = [vocab.channels[i].name for i, _ in vocab.resolve(target).channels]
        if match(target) or (chans and all(match(c) or match(c[:-2]) for c in chans)):
            ok.add(ctl)
    return ok
