"""Loading the simulator's segmentation datasets (`landing-sim dataset ...`).

A dataset directory holds RGB PNGs and 8-bit label PNGs (value = SemanticClass id, 0 = unknown).
Pairs are found from a manifest when there is one (`manifest.json` / `manifest.jsonl`, entries with
an image path and a label path), else by file name: `images/X.png` + `labels/X.png`, or
`X_rgb.png`/`X.png` + `X_label.png`/`X_labels.png` side by side.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from PIL import Image

from .models import MEAN, STD


def _manifest_pairs(root: Path) -> list[tuple[Path, Path]] | None:
    for name in ("manifest.jsonl", "manifest.json"):
        path = root / name
        if not path.exists():
            continue
        text = path.read_text()
        if name.endswith(".jsonl"):
            entries = [json.loads(line) for line in text.splitlines() if line.strip()]
        else:
            doc = json.loads(text)
            entries = doc if isinstance(doc, list) else next(
                (v for v in doc.values() if isinstance(v, list) and v and isinstance(v[0], dict)), [])
        pairs = []
        for e in entries:
            img = next((e[k] for k in ("image", "rgb", "image_path", "rgb_path", "color") if k in e), None)
            lab = next((e[k] for k in ("label", "labels", "label_path", "labels_path", "mask") if k in e), None)
            if img is None or lab is None:
                continue
            pairs.append((root / img, root / lab))
        if pairs:
            return pairs
    return None


def find_pairs(root: str | Path) -> list[tuple[Path, Path]]:
    root = Path(root)
    pairs = _manifest_pairs(root)
    if pairs is None:
        pairs = []
        if (root / "images").is_dir():
            for img in sorted((root / "images").glob("*.png")):
                for lab_dir in ("labels", "label", "masks"):
                    lab = root / lab_dir / img.name
                    if lab.exists():
                        pairs.append((img, lab))
                        break
        else:
            for lab in sorted(list(root.glob("*_label.png")) + list(root.glob("*_labels.png"))):
                stem = lab.name.rsplit("_", 1)[0]
                for cand in (f"{stem}_rgb.png", f"{stem}_image.png", f"{stem}.png", f"{stem}_rgb.jpg"):
                    if (root / cand).exists():
                        pairs.append((root / cand, lab))
                        break
    if not pairs:
        raise FileNotFoundError(f"no image/label pairs found in {root}")
    return sorted(pairs)


def load_split(root: str | Path, limit: int | None = None, size: tuple[int, int] | None = None):
    """Returns (images uint8 [N, H, W, 3], labels uint8 [N, H, W]), resized to size=(W, H) if
    given (bilinear for images, nearest for labels)."""
    pairs = find_pairs(root)
    if limit:
        pairs = pairs[:limit]
    read = [_read_pair(img, lab, size) for img, lab in pairs]
    return np.stack([r[0] for r in read]), np.stack([r[1] for r in read])


def _read_pair(img_path: Path, lab_path: Path, size: tuple[int, int] | None):
    img = Image.open(img_path).convert("RGB")
    lab = Image.open(lab_path)
    if lab.mode not in ("L", "P"):
        lab = lab.convert("L")
    if size is not None and img.size != size:
        img = img.resize(size, Image.BILINEAR)
    if size is not None and lab.size != size:
        lab = lab.resize(size, Image.NEAREST)
    if img.size != lab.size:
        raise ValueError(f"{img_path} is {img.size} but {lab_path} is {lab.size}")
    return np.asarray(img, dtype=np.uint8), np.asarray(lab, dtype=np.uint8)


_MEAN = torch.tensor(MEAN).view(1, 3, 1, 1)
_STD = torch.tensor(STD).view(1, 3, 1, 1)


def to_input(images_u8: np.ndarray | torch.Tensor) -> torch.Tensor:
    """uint8 [N, H, W, 3] -> normalised float [N, 3, H, W] (same as landing_perception::preprocess)."""
    x = torch.as_tensor(images_u8).permute(0, 3, 1, 2).float() / 255.0
    return (x - _MEAN) / _STD


def to_target(labels_u8: np.ndarray | torch.Tensor) -> torch.Tensor:
    """SemanticClass ids -> training targets: id - 1, unknown (0) -> 255 (ignored)."""
    y = torch.as_tensor(labels_u8).long() - 1
    y[y < 0] = 255
    return y


class LazySplit:
    """A dataset read on demand, a batch at a time, so that tens of thousands of images need
    neither the memory to hold them nor minutes to load before the first step. Same pairs, order
    and resizing as `load_split`."""

    def __init__(self, root: str | Path, limit: int | None = None,
                 size: tuple[int, int] | None = None):
        self.root = Path(root)
        self.pairs = find_pairs(root)
        if limit:
            self.pairs = self.pairs[:limit]
        self.size = size
        first, _ = self.batch([0])
        self.height, self.width = first.shape[1:3]

    def __len__(self) -> int:
        return len(self.pairs)

    def batch(self, indices) -> tuple[np.ndarray, np.ndarray]:
        """(images uint8 [B, H, W, 3], labels uint8 [B, H, W]) of the given indices."""
        pairs = [_read_pair(*self.pairs[int(i)], self.size) for i in indices]
        return np.stack([p[0] for p in pairs]), np.stack([p[1] for p in pairs])
