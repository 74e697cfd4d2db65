"""Moving code does not change results: `simulate`, `sweep`, `synth` and
`diagnose` on small cases write the same bytes as the code did before the
structure issue moved it (stored in tests/golden/expected; clock values such
as wall times are masked, see tests/golden/cases.py)."""

from __future__ import annotations

import difflib
import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "golden"))
import cases  # noqa: E402

EXPECTED = cases.HERE / "expected"


@pytest.mark.slow
def test_command_outputs_are_byte_identical_to_the_stored_ones(tmp_path):
    manifest = json.loads((EXPECTED / "MANIFEST.json").read_text())
    if manifest["versions"] != cases.versions():
        pytest.skip(f"stored under {manifest['versions']}, installed {cases.versions()}: "
                    "another Drake/NumPy/SciPy may round differently")
    cases.run_cases(tmp_path)
    files = cases.output_files(tmp_path)
    assert sorted(files) == sorted(manifest["sha256"]), "a command wrote other files"
    differ = []
    for rel, data in files.items():
        if cases.sha256(data) == manifest["sha256"][rel]:
            continue
        first = ""
        if (EXPECTED / rel).exists():
            old = (EXPECTED / rel).read_bytes().decode(errors="replace").splitlines()
            new = data.decode(errors="replace").splitlines()
            # The first removed line and the first added one (stored, new).
            lines = [d for d in difflib.unified_diff(old, new, n=0, lineterm="")
                     if d[:1] in "+-" and d[:3] not in ("+++", "---")]
            first = "".join(f"\n    {d}" for d in
                            [next((d for d in lines if d[0] == c), "") for c in "-+"] if d)
        differ.append(rel + first)
    assert not differ, "outputs changed:\n  " + "\n  ".join(differ)
