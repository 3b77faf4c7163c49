"""Everyday words for haptic attributes: what ``TextInterpreter`` reads before it asks the
sentence-embedding model.

A sentence-embedding model places antonyms side by side (all-MiniLM-L6-v2 gives "hard" and
"soft" a cosine of 0.55, "rough" and "soft" 0.64), so it cannot tell which of two opposite
attributes a word means. The readings here are therefore explicit: a phrase (one to four
words, lower case, matched whole) gives values to attributes. 1.0 means "has it", 0.0 "has
not"; a material gives the values such material usually has, at ``MATERIAL`` strength.
An attribute that is not listed (one added to the vocabulary at run time, e.g. "rubbery")
is matched by its own name and, failing that, by the embedding model.
"""

from __future__ import annotations

#: strength of a value that follows from a material ("steel" is usually cool) rather than
#: from a word about the feel
MATERIAL = 0.8

_WORDS: dict[str, dict[str, float]] = {
    # hardness
    "hard": {"hard": 1.0, "soft": 0.0},
    "stiff": {"hard": 1.0, "soft": 0.0, "compressible": 0.0},
    "rigid": {"hard": 1.0, "soft": 0.0, "compressible": 0.0},
    "firm": {"hard": 1.0, "soft": 0.0},
    "solid": {"solid": 1.0, "hard": 1.0},
    "doesn't give": {"hard": 1.0, "compressible": 0.0},
    "does not give": {"hard": 1.0, "compressible": 0.0},
    "soft": {"soft": 1.0, "hard": 0.0},
    "squishy": {"squishy": 1.0, "compressible": 1.0, "hard": 0.0},
    "squashy": {"squishy": 1.0, "compressible": 1.0, "hard": 0.0},
    "squashes": {"squishy": 1.0, "compressible": 1.0},
    "squash": {"squishy": 1.0, "compressible": 1.0},
    "squeezable": {"squishy": 1.0, "compressible": 1.0},
    "spongy": {"squishy": 1.0, "compressible": 1.0, "absorbent": 1.0, "porous": 1.0},
    "mushy": {"squishy": 1.0, "soft": 1.0},
    "compressible": {"compressible": 1.0},
    "gives way": {"compressible": 1.0, "hard": 0.0},
    "gives": {"compressible": 1.0},
    "dents": {"compressible": 1.0},
    "flexes": {"compressible": 1.0},
    "springy": {"springy": 1.0},
    "bouncy": {"springy": 1.0},
    "elastic": {"springy": 1.0},
    "stretchy": {"springy": 1.0},
    "springs back": {"springy": 1.0},
    "resilient": {"springy": 1.0},
    "spring": {"springy": 1.0},
    "rubbery": {"springy": 1.0},
    # surface
    "smooth": {"smooth": 1.0, "rough": 0.0},
    "glossy": {"smooth": 1.0, "slippery": 1.0, "rough": 0.0},
    "shiny": {"smooth": 1.0, "rough": 0.0},
    "polished": {"smooth": 1.0, "rough": 0.0},
    "silky": {"smooth": 1.0, "soft": 1.0},
    "sleek": {"smooth": 1.0},
    "slippery": {"slippery": 1.0},
    "slick": {"slippery": 1.0, "smooth": 1.0},
    "greasy": {"slippery": 1.0},
    "slimy": {"slippery": 1.0},
    "like glass": {"slippery": 1.0, "smooth": 1.0, "hard": 1.0},
    "grips": {"slippery": 0.0},
    "rough": {"rough": 1.0, "smooth": 0.0},
    "coarse": {"rough": 1.0, "smooth": 0.0},
    "gritty": {"rough": 1.0, "smooth": 0.0},
    "grainy": {"rough": 1.0, "textured": 1.0},
    "sanded": {"rough": 1.0},
    "uneven": {"bumpy": 1.0, "rough": 1.0},
    "scratchy": {"scratchy": 1.0, "rough": 1.0},
    "prickly": {"scratchy": 1.0},
    "abrasive": {"scratchy": 1.0, "rough": 1.0},
    "scrubbing": {"scratchy": 1.0},
    "itchy": {"scratchy": 1.0},
    "bumpy": {"bumpy": 1.0, "textured": 1.0, "smooth": 0.0},
    "lumpy": {"bumpy": 1.0},
    "lumps": {"bumpy": 1.0},
    "bumps": {"bumpy": 1.0},
    "ridged": {"bumpy": 1.0, "textured": 1.0},
    "ribbed": {"bumpy": 1.0, "textured": 1.0},
    "textured": {"textured": 1.0},
    "texture": {"textured": 1.0},
    "woven": {"textured": 1.0},
    "patterned": {"textured": 1.0},
    "fuzzy": {"fuzzy": 1.0},
    "furry": {"fuzzy": 1.0, "hairy": 1.0},
    "fluffy": {"fuzzy": 1.0, "soft": 1.0},
    "velvety": {"fuzzy": 1.0, "soft": 1.0},
    "plush": {"fuzzy": 1.0, "soft": 1.0},
    "hairy": {"hairy": 1.0},
    "fibres": {"hairy": 1.0},
    "fibers": {"hairy": 1.0},
    "bristly": {"hairy": 1.0, "scratchy": 1.0},
    "woolly": {"fuzzy": 1.0, "hairy": 1.0},
    "wool": {"fuzzy": 1.0},
    # temperature
    "cool": {"cool": 1.0},
    "cold": {"cool": 1.0},
    "chilly": {"cool": 1.0},
    "cold to the touch": {"cool": 1.0},
    "warm": {"cool": 0.0},
    # holes and water
    "porous": {"porous": 1.0},
    "holes": {"porous": 1.0},
    "holey": {"porous": 1.0},
    "full of holes": {"porous": 1.0},
    "open cell": {"porous": 1.0},
    "absorbent": {"absorbent": 1.0},
    "absorbs": {"absorbent": 1.0},
    "absorbs water": {"absorbent": 1.0},
    "soaks up": {"absorbent": 1.0},
    "soaks up water": {"absorbent": 1.0},
    "drinks up water": {"absorbent": 1.0},
    "drinks up": {"absorbent": 1.0},
    "waterproof": {"absorbent": 0.0},
    # size
    "thick": {"thick": 1.0},
    "chunky": {"thick": 1.0},
    "bulky": {"thick": 1.0},
    "thin": {"thick": 0.0},
    "flat": {"thick": 0.0},
    "metallic": {"metallic": 1.0},
}

#: materials and the values such material usually has (at ``MATERIAL`` strength)
_MATERIALS: dict[str, dict[str, float]] = {
    "metal": {"metallic": 1.0, "hard": 1.0, "cool": 1.0, "smooth": 1.0},
    "steel": {"metallic": 1.0, "hard": 1.0, "cool": 1.0, "smooth": 1.0},
    "aluminium": {"metallic": 1.0, "hard": 1.0, "cool": 1.0, "smooth": 1.0},
    "aluminum": {"metallic": 1.0, "hard": 1.0, "cool": 1.0, "smooth": 1.0},
    "iron": {"metallic": 1.0, "hard": 1.0, "cool": 1.0},
    "copper": {"metallic": 1.0, "hard": 1.0, "cool": 1.0},
    "glass": {"hard": 1.0, "smooth": 1.0, "cool": 1.0, "slippery": 1.0},
    "ceramic": {"hard": 1.0, "smooth": 1.0, "cool": 1.0},
    "plastic": {"hard": 1.0, "smooth": 1.0},
    "acrylic": {"hard": 1.0, "smooth": 1.0},
    "wood": {"hard": 1.0, "solid": 1.0},
    "wooden": {"hard": 1.0, "solid": 1.0},
    "mdf": {"hard": 1.0, "solid": 1.0},
    "stone": {"hard": 1.0, "cool": 1.0, "solid": 1.0},
    "concrete": {"hard": 1.0, "rough": 1.0, "cool": 1.0, "solid": 1.0},
    "brick": {"hard": 1.0, "rough": 1.0, "solid": 1.0},
    "cork": {"porous": 1.0, "compressible": 1.0},
    "cardboard": {"hard": 1.0, "smooth": 1.0},
    "paper": {"smooth": 1.0},
    "foam": {"soft": 1.0, "squishy": 1.0, "compressible": 1.0},
    "sponge": {"soft": 1.0, "squishy": 1.0, "absorbent": 1.0, "porous": 1.0},
    "rubber": {"springy": 1.0, "compressible": 1.0},
    "cotton": {"soft": 1.0, "absorbent": 1.0},
    "cloth": {"soft": 1.0},
    "fabric": {"soft": 1.0},
    "felt": {"soft": 1.0, "fuzzy": 1.0},
    "fleece": {"soft": 1.0, "fuzzy": 1.0},
    "microfiber": {"soft": 1.0, "fuzzy": 1.0},
    "tissue": {"soft": 1.0, "absorbent": 1.0},
    "tissues": {"soft": 1.0, "absorbent": 1.0},
    "leather": {"smooth": 1.0},
    "bubble": {"bumpy": 1.0},
    "bubbles": {"bumpy": 1.0},
    "loofah": {"rough": 1.0, "scratchy": 1.0, "porous": 1.0},
}


def readings() -> dict[str, tuple[dict[str, float], float]]:
    """Phrase -> (attribute values, strength): the direct words at 1, materials at
    ``MATERIAL``. A phrase in both is read as a direct word."""
    out = {p: (v, MATERIAL) for p, v in _MATERIALS.items()}
    out.update({p: (v, 1.0) for p, v in _WORDS.items()})
    return out


#: words that negate the reading after them in the same clause
NEGATIONS = frozenset(
    "not no never without hardly barely isn't aren't doesn't don't wasn't won't nor "
    "neither n't".split()
)
#: words that make a reading stronger, and weaker
STRONG = frozenset("very extremely really super so totally completely quite incredibly".split())
WEAK = frozenset("slightly somewhat mildly fairly bit little rather kinda partly".split())
#: words read as nothing on their own (articles, fillers, modifiers)
STOP = frozenset(
    "a an the it its it's is are was be this that of to in on at for by as like one side "
    "other and but with feels feel when you your yet or so very really slightly somewhat "
    "bit little not no quite has have made from up down".split()
)
