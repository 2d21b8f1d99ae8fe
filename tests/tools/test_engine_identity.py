"""tools/engine_identity.py keeps working: it fingerprints both reproductions and tells equal from different."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

TOOL = Path(__file__).resolve().parents[2] / "tools" / "engine_identity.py"


@pytest.mark.slow
def test_engine_identity_fingerprints_and_compares(tmp_path: Path) -> None:
    out = tmp_path / "fingerprint.npz"
    done = subprocess.run([sys.executable, str(TOOL), str(out)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    arrays = dict(np.load(out))
    assert any(k.startswith("four_rooms/") for k in arrays) and any(k.startswith("pinball/") for k in arrays)
    same = subprocess.run([sys.executable, str(TOOL), "--compare", str(out), str(out)], capture_output=True, text=True)
    assert same.returncode == 0 and f"{len(arrays)} of {len(arrays)} arrays identical" in same.stdout
    key = next(k for k in sorted(arrays) if k.endswith("/steps"))
    arrays[key] = arrays[key] + 1
    changed = tmp_path / "changed.npz"
    np.savez(changed, **arrays)  # type: ignore[arg-type]
    differs = subprocess.run(
        [sys.executable, str(TOOL), "--compare", str(out), str(changed)], capture_output=True, text=True
    )
    assert differs.returncode == 1 and f"differs: {key}" in differs.stdout
