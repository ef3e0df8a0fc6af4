"""Which face a command runs on: `--face SPEC` and the saved identities of the scanned head.

    --face ict                the scanned head (ICT FaceKit), its generic identity
    --face ict?identity=SEED  a character: identity weights np.random.default_rng(SEED).standard_normal(100)
    --face procedural         the procedural face (with --resolution 0, 1 or 2)
    --face NAME               an identity saved with `puppet face save NAME --identity SEED|w1,w2,...`

Without --face (and --rig) a command uses $PUPPET_FACE, else the scanned head's generic identity.
`--rig` and `--face` together are refused (the rig won, silently); so is `--resolution` with a face
other than the procedural one or with a rig (it was ignored).

Saved identities are small JSON files in the user's data folder ($PUPPET_DATA_DIR, else
$XDG_DATA_HOME/facepuppet/identities, else ~/.local/share/facepuppet/identities), written to a
temporary file and renamed into place. A take records the face it was made with (the spec, the
identity weights themselves and the rig's hash), so a replay rebuilds it even after the saved name
changed or went away."""

from __future__ import annotations

import errno
import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from puppet.errors import ConfigError, PuppetError

FORMAT = "facepuppet-identity"
VERSION = 1
N_IDENTITY = 100
#: The face every command uses when neither --face nor --rig is given ($PUPPET_FACE overrides it).
DEFAULT_FACE = "ict"
ENV = "PUPPET_FACE"
KINDS = ("ict", "procedural")
NAME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_-]{0,63}$")
FORMS = "ict, ict?identity=SEED, procedural or a saved identity's NAME"


@dataclass(frozen=True)
class FaceChoice:
    """A face asked for: `kind` "ict" (the scanned head, with `identity` weights, None = generic)
    or "procedural" (at `resolution`); `spec` is the text a take records and --face accepts."""

    kind: str
    spec: str
    identity: tuple[float, ...] | None = None
    resolution: int = 0

    @property
    def weights(self) -> np.ndarray:
        """(100,) float64 identity weights (zeros: the generic head)."""
        w = np.zeros(N_IDENTITY)
        if self.identity is not None:
            w[:len(self.identity)] = self.identity
        return w

    def identity_hash(self) -> str:
        """A short digest of the identity weights (float64 bytes), as a take and a cache name it."""
        return hashlib.sha256(self.weights.astype("<f8").tobytes()).hexdigest()[:16]

    def header(self) -> dict[str, Any]:
        """What a take records of this face (with the rig's name and hash, added by the caller)."""
        out: dict[str, Any] = {"face": self.spec}
        if self.kind == "ict":
            out["identity"] = [float(x) for x in self.weights]
            out["identity_hash"] = self.identity_hash()
        else:
            out["resolution"] = self.resolution
        return out


def default_face() -> str:
    """The --face used when none is given: $PUPPET_FACE, else DEFAULT_FACE (the scanned head)."""
    return os.environ.get(ENV) or DEFAULT_FACE


def seed_identity(seed: int) -> tuple[float, ...]:
    """The identity weights of a seed: 100 draws of N(0, 1) (the toolkit's own prior)."""
    return tuple(float(x) for x in np.random.default_rng(seed).standard_normal(N_IDENTITY))


def parse_identity(text: str) -> tuple[tuple[float, ...], int | None]:
    """`--identity SEED` (an integer >= 0) or `w1,w2,...` (1 to 100 finite numbers, the rest 0):
    (weights, seed or None). ValueError names the expected form."""
    t = text.strip()
    if re.fullmatch(r"\d{1,18}", t):
        seed = int(t)
        return seed_identity(seed), seed
    if re.fullmatch(r"\d{19,}", t):  # was "expected 1 to 100 finite weights", of a seed
        raise ValueError(f"--identity {text:.40}: a seed has at most 18 digits")
    try:
        vals = [float(x) for x in t.split(",")]
    except ValueError:
        raise ValueError(f"--identity {text!r}: expected a seed (an integer >= 0) or up to 100 weights "
                         "w1,w2,... (numbers)") from None
    if not 1 <= len(vals) <= N_IDENTITY or not all(np.isfinite(vals)) or max(abs(v) for v in vals) > 10:
        raise ValueError(f"--identity {text!r}: expected 1 to 100 finite weights within -10..10")
    return tuple(vals + [0.0] * (N_IDENTITY - len(vals))), None


def parse_face(spec: str | None, resolution: int = 0) -> FaceChoice:
    """The face a --face text names (None: the default face). PuppetError with the expected forms."""
    if spec is None and os.environ.get(ENV):
        try:
            return _parse_face(default_face(), resolution)
        except PuppetError as err:  # the user gave no --face: name where the face came from
            raise PuppetError(str(err).replace("--face ", f"${ENV} ", 1)) from err
    return _parse_face(spec if spec is not None else DEFAULT_FACE, resolution)


def _parse_face(spec: str, resolution: int) -> FaceChoice:
    text = spec.strip()
    base, _, query = text.partition("?")
    if base == "procedural":
        if query:
            raise PuppetError(f"--face {text!r}: procedural takes no options (use --resolution N)")
        if resolution not in (0, 1, 2):
            raise PuppetError(f"--resolution {resolution}: valid resolutions are 0, 1, 2")
        return FaceChoice("procedural", "procedural", None, resolution)
    if base == "ict":
        if not query:
            return FaceChoice("ict", "ict")
        key, _, value = query.partition("=")
        if key != "identity" or not re.fullmatch(r"\d{1,18}", value):
            raise PuppetError(f"--face {text!r:.60}: expected ict or ict?identity=SEED (SEED an integer >= 0 of at "
                              "most 18 digits)")
        return FaceChoice("ict", f"ict?identity={int(value)}", seed_identity(int(value)))
    if query or not NAME_RE.match(base):
        raise PuppetError(f"--face {text!r}: expected {FORMS}")
    weights = load_identity(base)
    return FaceChoice("ict", base, weights)


def recorded_face(rig: dict[str, Any]) -> FaceChoice | None:
    """The face a take's header names (its spec and identity weights), or None for a take made
    before faces were recorded (or with a rig file)."""
    spec = rig.get("face")
    if not isinstance(spec, str):
        return None
    if spec == "procedural" or "identity" not in rig:
        return parse_face("procedural" if spec == "procedural" else spec, int(rig.get("resolution", 0) or 0))
    return FaceChoice("ict", spec, tuple(float(x) for x in rig["identity"]))


# ------------------------------------------------------------------------------ saved identities

def data_dir() -> Path:
    """Where saved identities live."""
    env = os.environ.get("PUPPET_DATA_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "facepuppet" / "identities"


def identity_path(name: str) -> Path:
    if not NAME_RE.match(name) or name in KINDS:
        raise PuppetError(f"identity name {name!r}: use a letter then letters, digits, - or _ (at most 64), "
                          f"not {' or '.join(KINDS)}")
    return data_dir() / f"{name}.json"


def save_identity(name: str, weights: tuple[float, ...], seed: int | None = None, replace: bool = True) -> Path:
    """Write the identity `name` atomically; returns its file. With `replace` False an identity of
    that name saved meanwhile (another `puppet face save` at the same moment) is never overwritten:
    the file is linked into place only where none is, and other weights found there are an error."""
    import json
    import tempfile

    from safefile import atomic_write

    path = identity_path(name)
    body = {"format": FORMAT, "version": VERSION, "name": name, "seed": seed,
            "identity": [float(x) for x in weights]}
    text = json.dumps(body, indent=1) + "\n"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        if replace:
            with atomic_write(path) as fh:
                fh.write(text)
            return path
        fd, made = tempfile.mkstemp(prefix=".identity.", suffix=".json", dir=path.parent)
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as fh:
                fh.write(text)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(made, 0o666 & ~_umask())
            try:
                os.link(made, path)  # fails where a file of that name is: nothing is replaced
            except FileExistsError:
                pass
            except OSError as err:  # a file system without hard links: the check and the rename
                if err.errno not in _NO_LINKS:
                    raise
                if not os.path.lexists(path):
                    os.replace(made, path)
                    return path
            else:
                return path
        finally:
            if os.path.lexists(made):
                os.unlink(made)
    except OSError as err:
        raise PuppetError(f"{path}: cannot save the identity: {err.strerror or err}") from err
    check_saved(name, path, weights, seed)
    return path


def check_saved(name: str, path: Path, weights: tuple[float, ...], seed: int | None) -> None:
    """Nothing at `path`, or the identity `name` saved there with these weights; anything else is
    one error line (a folder, pipe or dangling link of that name says what it is)."""
    if not os.path.lexists(path):
        return
    if not path.is_file():
        what = "a folder" if path.is_dir() else "a broken link" if path.is_symlink() else "not a file"
        raise PuppetError(f"{path}: {what} has the identity {name}'s file name: move it, or choose another name")
    try:
        same = read_identity(path)[1:] == (tuple(float(x) for x in weights), seed)
    except Exception:  # an unreadable file of that name is not silently replaced either
        same = False
    if not same:
        raise PuppetError(f"an identity named {name} is already saved ({path}) with other weights: "
                          "add --replace to replace it, or choose another name")


#: errno values of a link(2) the file system does not offer.
_NO_LINKS = frozenset(getattr(errno, n) for n in ("EPERM", "ENOTSUP", "EOPNOTSUPP", "ENOSYS") if hasattr(errno, n))


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def read_identity(path: Path) -> tuple[str, tuple[float, ...], int | None]:
    """(name, weights, seed) of a saved identity file; ConfigError (one line naming the file) if it
    is not one."""
    from safefile import BadFile, load_json, number, read_text, sequence, table

    try:
        doc = table(load_json(read_text(path, "identity", 1 << 20), str(path), "identity"), str(path))
        if doc.get("format") != FORMAT:
            raise BadFile(f"{path}: not a facepuppet identity (format is not {FORMAT!r})")
        if doc.get("version") != VERSION:
            raise BadFile(f"{path}: identity version {doc.get('version')!r} is not supported (expected {VERSION})")
        vals = sequence(doc.get("identity"), f"{path}: identity", N_IDENTITY, 1)
        weights = tuple(number(v, f"{path}: identity weight {k + 1}", -10, 10) for k, v in enumerate(vals))
        seed = doc.get("seed")
        if seed is not None:
            seed = int(number(seed, f"{path}: seed", 0, 10**18, integer=True))
    except BadFile as err:
        raise ConfigError(f"{err}; save it again with `puppet face save NAME --identity ...`") from err
    return path.stem, weights + (0.0,) * (N_IDENTITY - len(weights)), seed


def load_identity(name: str) -> tuple[float, ...]:
    """The weights of a saved identity; PuppetError if there is none of that name."""
    path = identity_path(name)
    if not path.is_file():
        raise PuppetError(f"--face {name}: no saved identity of that name in {path.parent} (expected {FORMS}; "
                          "`puppet face list` shows the saved ones)")
    return read_identity(path)[1]


def list_identities() -> list[tuple[str, tuple[float, ...] | None, int | None, str]]:
    """(name, weights or None, seed, problem) of every saved identity file, sorted by name."""
    folder = data_dir()
    out = []
    for path in sorted(folder.glob("*.json")) if folder.is_dir() else []:
        if not path.is_file():  # a pipe there made the list wait for a writer, forever
            out.append((path.stem, None, None, f"{path}: not a regular file; remove it or save the identity again"))
            continue
        try:
            name, w, seed = read_identity(path)
            out.append((name, w, seed, ""))
        except ConfigError as err:
            out.append((path.stem, None, None, str(err)))
    return out
