"""Built-in tactile simulator: a PHAC-2-like dataset of 32 x 30 tactile images.

Layout follows the paper (Sect. V-A): 4 exploratory procedures x 8 readings
(PDC, PAC, TAC, TDC, 4 electrode principal components) = 32 channels, 30 steps.
Attributes act on the signals only through a few latent physical properties
(stiffness, compliance, conductivity, ...), which every object perturbs, so
attributes are learnable but not perfectly separable and same-attribute objects differ.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from app.data.dataset import TactileDataset

PAPER_ATTRIBUTES: tuple[str, ...] = (
    "absorbent", "bumpy", "compressible", "cool", "fuzzy", "hard", "hairy", "metallic",
    "porous", "rough", "scratchy", "slippery", "smooth", "soft", "solid", "springy",
    "squishy", "textured", "thick",
)  # fmt: skip
PROCEDURES: tuple[str, ...] = ("squeeze", "hold", "slide", "move_down")
READINGS: tuple[str, ...] = ("pdc", "pac", "tac", "tdc", "e0", "e1", "e2", "e3")
CHANNEL_NAMES: tuple[str, ...] = tuple(f"{p}/{r}" for p in PROCEDURES for r in READINGS)
N_STEPS = 30
DEFAULT_NOISE = 0.12


def channel(procedure: str, reading: str) -> int:
    """Index of a (procedure, reading) channel in the 32-channel layout."""
    return PROCEDURES.index(procedure) * len(READINGS) + READINGS.index(reading)


# Material archetypes: attribute probabilities loosely matching PHAC-2's co-occurrences.
_ARCHETYPES: tuple[dict[str, float], ...] = (
    {"absorbent": .6, "compressible": .95, "squishy": .9, "soft": .7, "porous": .5,
     "springy": .45, "thick": .15, "textured": .15, "bumpy": .1},  # foam / sponge
    {"fuzzy": .75, "hairy": .35, "soft": .7, "compressible": .5, "squishy": .45,
     "absorbent": .35, "textured": .25, "thick": .1},  # soft fabric
    {"hairy": .6, "rough": .85, "scratchy": .75, "textured": .85, "fuzzy": .35,
     "thick": .2, "solid": .15, "squishy": .15},  # coarse fibre
    {"metallic": .85, "cool": .9, "hard": .8, "solid": .9, "smooth": .85,
     "slippery": .5, "thick": .3},  # metal
    {"hard": .75, "solid": .75, "smooth": .9, "slippery": .45, "cool": .35,
     "thick": .2, "textured": .1},  # smooth plastic / glass
    {"hard": .9, "solid": .9, "rough": .75, "textured": .8, "scratchy": .25,
     "thick": .45, "bumpy": .1},  # rough hard (wood, brick, cork)
    {"compressible": .7, "squishy": .65, "smooth": .55, "slippery": .3, "bumpy": .25,
     "textured": .2, "springy": .2, "thick": .15, "soft": .2},  # flexible packaging
)  # fmt: skip
_FLOOR = 0.02  # any compatible attribute can occur, rarely, on any material

# Pairs that never co-occur in PHAC-2 and are physically implausible together.
_RIGID, _COMPLIANT = (
    ("hard", "solid", "metallic"),
    ("soft", "squishy", "compressible", "springy", "absorbent", "porous"),
)
_EXCLUSIONS: tuple[tuple[tuple[str, ...], tuple[str, ...]], ...] = (
    (_RIGID, _COMPLIANT),
    (("hard", "metallic"), ("fuzzy", "hairy")),
    (("smooth", "slippery"), ("rough", "scratchy", "hairy", "fuzzy", "bumpy")),
    (("cool",), ("fuzzy", "hairy", "soft", "absorbent", "porous", "springy", "rough", "scratchy")),
)  # fmt: skip

# Latent physical properties as linear functions of attributes (weights by name, "_base" intercept).
_PROPERTIES: dict[str, dict[str, float]] = {
    "stiff": {"hard": .9, "solid": .5, "metallic": .4, "soft": -.5, "squishy": -.45,
              "compressible": -.45, "absorbent": -.2, "springy": -.1},
    "comp": {"compressible": .5, "squishy": .45, "soft": .35, "porous": .2, "fuzzy": .15,
             "hard": -.25},
    "cond": {"metallic": .8, "cool": .55, "fuzzy": -.15, "hairy": -.15, "porous": -.1},
    "rough": {"rough": .6, "textured": .4, "scratchy": .55, "bumpy": .2},
    "pitch": {"scratchy": .5, "rough": .2, "textured": .1, "bumpy": -.3},
    "bumps": {"bumpy": .8, "textured": .15},
    "fric": {"_base": .6, "slippery": -.35, "smooth": -.15, "rough": .2, "fuzzy": .15,
             "textured": .1},
    "fuzz": {"fuzzy": .5, "hairy": .45},
    "thick": {"thick": .8},
    "spring": {"springy": .8},
    "relax": {"absorbent": .5, "porous": .45, "soft": .1},
}  # fmt: skip
_OBJECT_SPREAD = 0.15  # same-attribute objects differ this much in each property
_INTENSITY = (0.4, 1.3)  # how strongly an object shows each attribute it is labelled with
_UNLABELLED = 0.05  # chance that an object weakly shows an attribute people did not name
_TRIAL_SPREAD = 0.1  # contact location/pose varies between trials
_FINGERPRINT = 0.055  # object-specific per-channel shape not explained by any property
_DRIFT = 0.1  # per-trial sensor offset and slope
_GAIN = 0.05  # per-trial, per-procedure contact gain

# separation="phac2": every object also gets a smooth signature of its own, _SIGNATURE_BASIS
# cosines per channel with N(0, a^2) weights, a growing with the number of objects N so that
# the median distance from an object's mean to the nearest other object's mean, in units of
# its trials' spread along that line (bench/separation.py), stays where PHAC-2's 60 real
# objects put it (5.5). The default simulator is there already at 60 objects (5.6, mean of
# 8 seeds) and falls below as N grows (4.4 at 3,000, 3.9 at 30,000). a at the sizes below
# was fitted with that script (seed 0); between them a^2 is linear in ln N, beyond the last
# it goes on along the last segment. 300, 1,000 and 10,000 objects check the fit.
SEPARATIONS: tuple[str, ...] = ("phac2",)
# modes > 1: each object is touched in one of several contact modes (grasp poses, contact
# locations), trial i of an object in mode i % modes, so training and held-out trials share
# them. Each object's modes are smooth signatures of its own (_in_modes), centred on it and
# larger than the distances between objects: its trials gather in as many clusters, its
# mean lies between them, where no trial is, and a model with one Gaussian per object loses
# (bench/compare_known.py measures it).
_MODE_SCALE = 0.3
_SIGNATURE_BASIS = 6
_SIGNATURE_FIT = {"phac2": ((60, 0.0), (3_000, 0.0153), (30_000, 0.0171))}  # (N, a)


def simulate_dataset(
    n_objects: int = 60,
    trials_per_object: int = 10,
    seed: int = 0,
    attribute_names: Sequence[str] = PAPER_ATTRIBUTES,
    noise: float = DEFAULT_NOISE,
    separation: str | None = None,
    modes: int = 1,
    channels: int = len(CHANNEL_NAMES),
    steps: int = N_STEPS,
) -> TactileDataset:
    """A deterministic PHAC-2-like dataset: samples (N, 32, 30), one sample per trial.

    ``noise`` is the std of white sensor noise (signals are O(1)); the default
    keeps held-out-trial accuracy of simple classifiers well below 100%.

    ``separation``: None (the default) draws every object from the 19 attributes, its
    latent properties and a small fingerprint, in a space of fixed size, so objects crowd
    together as their number grows. ``"phac2"`` adds to each object a smooth signature of
    its own whose amplitude grows with ``n_objects`` so that the nearest other object stays
    as far away, in units of trial spread, as it is among PHAC-2's 60 real objects, at any
    number of objects (measured by ``bench/separation.py``; fitted at 3,000 and 30,000
    objects, checked at 300, 1,000 and 10,000; up to 60 objects it adds nothing). The
    signature is drawn from a generator of its own, so every other value is the same as
    with None.

    ``modes``: how many contact modes each object shows (1, the default, adds nothing).
    Trial i of an object is touched in mode i % modes; each mode moves the object's trials by a
    smooth signature of its own, the object's modes centred on it (drawn from a generator of
    its own, so every other value is the same as with 1).

    ``channels`` and ``steps``: a sensor of many taxels (a GelSight image, an event array)
    instead of the 32 readings: samples (N, ``channels``, ``steps``). Each procedure's 8
    readings, resampled to ``steps`` steps, are seen by ``channels / 4`` taxels, each a
    weighted sum of them whose weights fall off smoothly along the array (every reading has a
    receptive field of its own), so neighbouring taxels are strongly correlated, plus white
    noise of std ``noise`` per taxel (``_taxels``; drawn from a generator of its own).
    ``channels`` must be a positive multiple of 4; the defaults (32, 30) add nothing.
    """
    if separation is not None and separation not in SEPARATIONS:
        raise ValueError(f"separation must be None or one of {SEPARATIONS}, got {separation!r}")
    names = tuple(attribute_names)
    unknown = [a for a in names if a not in PAPER_ATTRIBUTES]
    if not names or unknown or len(set(names)) != len(names):
        raise ValueError(
            f"attribute_names must be distinct names from {PAPER_ATTRIBUTES}, got {names}"
        )
    if n_objects < 1 or trials_per_object < 1 or noise < 0:
        raise ValueError("n_objects and trials_per_object must be >= 1 and noise >= 0")
    if not isinstance(modes, int | np.integer) or modes < 1:
        raise ValueError(f"modes must be an integer >= 1, got {modes!r}")
    n_procedures = len(PROCEDURES)
    if not isinstance(channels, int | np.integer) or channels < 1 or channels % n_procedures:
        raise ValueError(
            f"channels must be a positive multiple of {n_procedures}, got {channels!r}"
        )
    if not isinstance(steps, int | np.integer) or steps < 2:
        raise ValueError(f"steps must be an integer >= 2, got {steps!r}")
    rng = np.random.default_rng(seed)
    full = sample_attributes(rng, n_objects, names)  # (K, 19) in PAPER_ATTRIBUTES order
    labels = np.repeat(np.arange(n_objects), trials_per_object)
    samples = _signals(rng, full, labels, noise)
    if separation is not None:
        own = np.random.default_rng([seed, 0x5E9])  # leaves the main stream as it was
        signature = _signature(own, n_objects, signature_scale(separation, n_objects))
        samples.reshape(n_objects, trials_per_object, *samples.shape[1:])[:] += signature[:, None]
    if modes > 1:
        samples = _in_modes(samples, trials_per_object, modes, seed)
    if channels != len(CHANNEL_NAMES) or steps != N_STEPS:
        samples = _taxels(samples, int(channels), int(steps), noise, seed)
    width = max(2, len(str(n_objects - 1)))
    cols = [PAPER_ATTRIBUTES.index(a) for a in names]
    return TactileDataset(
        samples=samples,
        labels=labels,
        trials=np.arange(len(labels)),
        class_attributes=full[:, cols].astype(np.float32),
        attribute_names=names,
        class_names=tuple(f"sim-object-{k:0{width}d}" for k in range(n_objects)),
        name="simulated",
        procedures=PROCEDURES,
    )


# ---------------------------------------------------------------- attribute vectors


def _conflicts() -> np.ndarray:
    m = len(PAPER_ATTRIBUTES)
    x = np.zeros((m, m), dtype=bool)
    for left, right in _EXCLUSIONS:
        for a in left:
            for b in right:
                i, j = PAPER_ATTRIBUTES.index(a), PAPER_ATTRIBUTES.index(b)
                x[i, j] = x[j, i] = True
    return x


def sample_attributes(
    rng: np.random.Generator, n_objects: int, allowed: Sequence[str] = PAPER_ATTRIBUTES
) -> np.ndarray:
    """(K, 19) 0/1 vectors over PAPER_ATTRIBUTES; only ``allowed`` columns are ever set.

    Each object gets 2-7 compatible attributes; vectors are distinct while the
    space allows, and with >= 20 objects every allowed attribute is used >= 3 times.
    """
    mask = np.isin(PAPER_ATTRIBUTES, list(allowed))
    probs = np.array([[a.get(n, 0.0) for n in PAPER_ATTRIBUTES] for a in _ARCHETYPES])
    probs = np.where(mask, np.maximum(probs, _FLOOR), 0.0)
    lo, hi = min(2, int(mask.sum())), min(7, int(mask.sum()))
    conflicts = _conflicts()
    vectors, kinds, seen = [], [], set()
    for _ in range(n_objects):
        for _attempt in range(60):  # rejection keeps vectors distinct
            kind = int(rng.integers(len(_ARCHETYPES)))
            v = _draw(rng, probs[kind], conflicts, lo, hi)
            if v.tobytes() not in seen:
                break
        seen.add(v.tobytes())
        vectors.append(v)
        kinds.append(kind)
    out = np.array(vectors)
    if n_objects >= 20:
        _cover(rng, out, probs[kinds], conflicts, hi, seen)
    return out.astype(np.float32)


def _draw(rng: np.random.Generator, p: np.ndarray, conflicts: np.ndarray, lo: int, hi: int):
    order = np.argsort(-p * rng.uniform(0.5, 1.0, p.shape))  # likelier attributes win conflicts
    hit = rng.random(p.shape) < p
    v = np.zeros(p.shape, dtype=bool)
    for j in order:
        if hit[j] and not (conflicts[j] & v).any():
            v[j] = True
    for j in order:  # top up to the minimum with compatible attributes
        if v.sum() >= lo:
            break
        if p[j] > 0 and not v[j] and not (conflicts[j] & v).any():
            v[j] = True
    for j in order[::-1]:  # trim the least likely beyond the maximum
        if v.sum() <= hi:
            break
        v[j] = False
    return v


def _cover(rng, v: np.ndarray, p: np.ndarray, conflicts: np.ndarray, hi: int, seen: set) -> None:
    """Give every attribute >= 3 objects, in place, preferring objects likely to carry it.

    First pass only adds; the second may also drop the object's conflicting or
    least likely attributes, as long as those stay used >= 3 times.
    """
    lo = min(2, int((p.max(axis=0) > 0).sum()))
    for swap in (False, True):
        for j in np.flatnonzero(p.max(axis=0) > 0):
            for i in np.argsort(-p[:, j] * rng.uniform(0.5, 1.0, len(v))):
                if v[:, j].sum() >= 3:
                    break
                if v[i, j]:
                    continue
                w = v[i] & ~conflicts[j]
                if w.sum() >= hi:  # make room by dropping the least likely attribute
                    w[np.flatnonzero(w)[np.argmin(p[i, w])]] = False
                w[j] = True
                dropped = v[i] & ~w
                if dropped.any() and (not swap or (v[:, dropped].sum(axis=0) <= 3).any()):
                    continue
                if w.sum() < lo or w.tobytes() in seen:
                    continue
                seen.discard(v[i].tobytes())
                seen.add(w.tobytes())
                v[i] = w


# ---------------------------------------------------------------- signals


def _properties(rng: np.random.Generator, attrs: np.ndarray) -> dict[str, np.ndarray]:
    """Latent physical properties per object: attribute effects plus object-specific spread.

    Human labels are coarse: labelled attributes act with varying strength and
    unlabelled ones sometimes act weakly, so attributes never explain signals fully.
    """
    strength = np.where(
        attrs > 0,
        rng.uniform(*_INTENSITY, attrs.shape),
        (rng.random(attrs.shape) < _UNLABELLED) * rng.uniform(0.3, 0.7, attrs.shape),
    )
    out = {}
    for prop, weights in _PROPERTIES.items():
        w = np.array([weights.get(a, 0.0) for a in PAPER_ATTRIBUTES])
        base = weights.get("_base", 0.0)
        out[prop] = base + strength @ w + rng.normal(0.0, _OBJECT_SPREAD, len(attrs))
    return out


def signature_scale(separation: str, n_objects: int) -> float:
    """The signature's amplitude (per channel and cosine) for ``n_objects`` objects."""
    sizes, amplitudes = np.array(_SIGNATURE_FIT[separation], dtype=np.float64).T
    x, y = np.log(sizes), amplitudes**2
    at = np.log(max(n_objects, 1))
    if at > x[-1]:  # beyond the fit: along its last segment
        a2 = y[-1] + (y[-1] - y[-2]) / (x[-1] - x[-2]) * (at - x[-1])
    else:
        a2 = np.interp(at, x, y)
    return float(np.sqrt(max(a2, 0.0)))


def _signature(rng: np.random.Generator, k: int, scale: float) -> np.ndarray:
    """(k, 32, 30) float32: per object and channel, _SIGNATURE_BASIS cosines over the trial
    (each of unit mean square) with independent N(0, scale^2) weights."""
    grid = np.linspace(0.0, 1.0, N_STEPS)
    basis = np.stack([np.cos(np.pi * m * grid) for m in range(_SIGNATURE_BASIS)])
    basis /= np.sqrt((basis**2).mean(axis=1, keepdims=True))
    out = np.empty((k, 32, N_STEPS), dtype=np.float32)
    for lo in range(0, k, 4096):  # bounded memory at tens of thousands of objects
        weights = rng.normal(0.0, scale, (min(k, lo + 4096) - lo, 32, _SIGNATURE_BASIS))
        out[lo : lo + len(weights)] = weights @ basis
    return out


def _in_modes(samples: np.ndarray, trials: int, modes: int, seed: int) -> np.ndarray:
    """Each trial's sample moved to its contact mode (trial % modes): per object, ``modes``
    smooth signatures (``_signature``) of amplitude _MODE_SCALE, centred on the object, so its
    mean stays where it was and its trials gather around points as far from it as from other
    objects."""
    k = len(samples) // trials
    rng = np.random.default_rng([seed, 0x30DE])
    out = samples.reshape(k, trials, *samples.shape[1:])
    mode = np.arange(trials) % modes
    for lo in range(0, k, 1024):  # bounded memory at tens of thousands of objects
        objects = min(k, lo + 1024) - lo
        offsets = _signature(rng, objects * modes, _MODE_SCALE).reshape(objects, modes, 32, -1)
        offsets -= offsets.mean(axis=1, keepdims=True)
        out[lo : lo + objects] += offsets[:, mode]
    return samples


def _taxels(samples: np.ndarray, channels: int, steps: int, noise: float, seed: int) -> np.ndarray:
    """(N, channels, steps) float32: each procedure's readings resampled to ``steps`` and seen
    by ``channels / 4`` taxels (``simulate_dataset``'s ``channels``)."""
    rng = np.random.default_rng([seed, 0x7A7E1])
    at = np.linspace(0.0, N_STEPS - 1, steps)
    lo = np.minimum(at.astype(np.int64), N_STEPS - 2)
    frac = (at - lo).astype(np.float32)
    per, readings = channels // len(PROCEDURES), len(READINGS)
    taxel = np.arange(per)[:, None]
    out = np.empty((len(samples), channels, steps), np.float32)
    for p in range(len(PROCEDURES)):
        own = samples[:, p * readings : (p + 1) * readings]
        x = own[..., lo] * (1.0 - frac) + own[..., lo + 1] * frac  # (N, 8, steps)
        centres = rng.uniform(0.0, per, readings)
        widths = rng.uniform(0.1, 0.3, readings) * per + 0.5
        weights = np.exp(-0.5 * ((taxel - centres) / widths) ** 2)  # (per, 8): smooth fields
        weights *= rng.uniform(0.5, 1.5, (per, readings))
        weights += rng.normal(0.0, 0.05, (per, readings))
        for lo_row in range(0, len(x), 1024):  # bounded memory at many samples
            rows = x[lo_row : lo_row + 1024]
            block = np.einsum("kr,nrt->nkt", weights.astype(np.float32), rows)
            block += rng.normal(0.0, noise, block.shape).astype(np.float32)
            out[lo_row : lo_row + len(rows), p * per : (p + 1) * per] = block
    return out


def _signals(rng: np.random.Generator, attrs: np.ndarray, labels: np.ndarray, noise: float):
    k, n, t = len(attrs), len(labels), N_STEPS
    props = _properties(rng, attrs)
    # Object fingerprint: small per-channel offset/slope/bump shared by all its trials.
    fingerprint = rng.normal(0.0, _FINGERPRINT, (k, 32, 3))
    pitch_obj = rng.normal(0.0, 0.8, k)  # texture wavelength differs per object
    # Per-trial properties: object value + pose variation, as (n, 1) for broadcasting.
    p = {
        name: (val[labels] + rng.normal(0.0, _TRIAL_SPREAD, n))[:, None]
        for name, val in props.items()
    }
    shift = rng.uniform(-0.05, 0.05, (n, 4, 1))  # per-trial, per-procedure time offsets
    u = np.linspace(0.0, 1.0, t)[None, None, :] - shift  # (n, 4, t)
    phase = rng.uniform(0.0, 2 * np.pi, (n, 4, 2))
    broadband = rng.normal(0.0, 1.0, (n, 4, t))

    x = np.zeros((n, 4, 8, t))
    stiff, comp, cond = p["stiff"], p["comp"], p["cond"]
    p["fric"] = np.maximum(p["fric"], 0.02)  # friction never vanishes
    amp = np.maximum(1.0 + 0.35 * stiff, 0.1)  # hard objects push back harder at the set grip
    deform = np.maximum(0.3 + comp, 0.02)  # compliant objects deform the fingertip more

    # Squeeze: contact, first-order pressure rise, springy overshoot, porous relaxation.
    s = u[:, 0]
    contact = np.maximum(s - (0.25 - 0.08 * p["thick"]), 0.0)  # thick: earlier contact
    rate = np.clip(4.0 * np.exp(0.8 * stiff), 1.0, 30.0)
    rise = 1.0 - np.exp(-rate * contact)
    # Springy rebound: a damped oscillation right after contact.
    bounce = np.exp(-6.0 * contact) * np.sin(2 * np.pi * 2.5 * contact)
    relax = 1.0 - 0.35 * p["relax"] * (1.0 - np.exp(-3.0 * contact))
    x[:, 0, 0] = amp * rise * relax + 0.8 * p["spring"] * bounce
    x[:, 0, 1] = (
        0.3
        * np.exp(-(((contact - 0.03) * 15) ** 2))
        * (contact > 0)
        * np.sin(2 * np.pi * 11 * s + phase[:, 0, :1])
        * (1 + 0.5 * np.tanh(stiff))
    )  # impact transient
    x[:, 0, 2] = -1.6 * cond * contact * np.exp(-4.0 * contact) * 4.0  # heat flux out of finger
    x[:, 0, 3] = -0.4 * cond * (1.0 - np.exp(-4.0 * contact))
    x[:, 0, 4] = deform * (1.0 - np.exp(-2.5 * np.exp(0.5 * stiff) * contact))  # slow for soft
    x[:, 0, 5] = 0.2 * p["fric"] * rise
    x[:, 0, 6] = 0.6 * p["thick"] + 0.3 * comp * rise  # aperture-related offset
    x[:, 0, 7] = 0.8 * p["spring"] * bounce

    # Hold: pressure relaxes (absorbent/porous), temperature keeps falling (cool/metallic).
    h = u[:, 1]
    end_relax = 1.0 - 0.35 * p["relax"]
    x[:, 1, 0] = (
        amp * end_relax * (1.0 - 0.4 * p["relax"] * (1.0 - np.exp(-3.0 * h))) - 0.1 * comp * h
    )
    x[:, 1, 1] = 0.25 * p["fuzz"] * broadband[:, 1]  # fibres settle
    x[:, 1, 2] = -1.5 * cond * np.exp(-2.5 * h)
    x[:, 1, 3] = -0.4 * cond - 0.6 * cond * (1.0 - np.exp(-2.5 * h))
    x[:, 1, 4] = deform * (1.0 + 0.15 * comp * (1.0 - np.exp(-2.0 * h)))  # creep
    x[:, 1, 5] = 0.2 * p["fric"]
    x[:, 1, 6] = 0.6 * p["thick"] + 0.3 * comp

    # Slide and move-down: texture vibration, friction shear, frictional heating.
    for proc, speed, gain in ((2, 1.0, 1.0), (3, 0.6, 0.7)):
        m = u[:, proc]
        env = 1.0 / (1.0 + np.exp(-(m - 0.15) * 40.0))  # motion starts
        f_hf = speed * (9.0 + 3.0 * p["pitch"] + pitch_obj[labels][:, None])
        f_b = speed * 3.0
        hf = np.sin(2 * np.pi * f_hf * m + phase[:, proc, :1])
        bump = np.sin(2 * np.pi * f_b * m + phase[:, proc, 1:])
        x[:, proc, 0] = gain * (0.8 * amp + env * (0.3 * p["bumps"] * bump + 0.1 * p["fric"]))
        x[:, proc, 1] = gain * env * (
            0.9 * np.maximum(p["rough"], 0) * hf + 0.6 * p["bumps"] * bump
            + 0.35 * p["fuzz"] * broadband[:, proc] + 0.08 * hf)  # fmt: skip
        x[:, proc, 2] = -0.3 * cond * np.exp(-2.0 * m) + 0.2 * p["fric"] * env
        x[:, proc, 3] = -cond + 0.15 * p["fric"] * np.cumsum(env, axis=-1) / t
        x[:, proc, 4] = 0.9 * deform + 0.1 * p["rough"] * hf
        x[:, proc, 5] = gain * 0.8 * p["fric"] * env * (1.0 + 0.2 * bump)  # shear
        x[:, proc, 6] = 0.6 * p["thick"] + 0.3 * comp
        x[:, proc, 7] = 0.3 * p["bumps"] * bump * env

    x = x.reshape(n, 32, t)
    grid = np.linspace(0.0, 1.0, t)
    basis = np.stack([np.ones(t), grid - 0.5, np.sin(np.pi * grid)])  # (3, t)
    x += fingerprint[labels] @ basis
    x *= rng.normal(1.0, _GAIN, (n, 4, 1, 1)).repeat(8, axis=2).reshape(n, 32, 1)  # contact gain
    drift = rng.normal(0.0, _DRIFT, (n, 32, 2))  # slow sensor drift: offset + slope per trial
    x += drift[..., :1] + drift[..., 1:] * grid
    x += rng.normal(0.0, noise, x.shape)
    return x.astype(np.float32)
