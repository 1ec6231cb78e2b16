"""Execute the notebooks in notebooks/ so they cannot rot (needs the `test` extra: nbclient, nbformat, ipykernel);
they are stored executed (notebooks/execute.py) and must stay so."""

from __future__ import annotations

import os
import time
from pathlib import Path

import pytest

nbformat = pytest.importorskip("nbformat")
nbclient = pytest.importorskip("nbclient")
pytest.importorskip("ipykernel")

NB_DIR = Path(__file__).resolve().parents[1] / "notebooks"
NOTEBOOKS = ["filter_vs_smoother.ipynb", "observability.ipynb", "acceleration_aiding.ipynb"]


def _run(name: str):
    nb = nbformat.read(NB_DIR / name, as_version=4)
    # Stored executed (notebooks/execute.py), so they read on any code host: every code cell ran,
    # none raised. Executed here again from a copy without outputs, which must not need them.
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert all(c.get("execution_count") for c in code), (
        f"{name}: stored unexecuted (python notebooks/execute.py)"
    )
    assert not any(o.get("output_type") == "error" for c in code for o in c.get("outputs", [])), (
        name
    )
    for c in code:
        c.outputs, c.execution_count = [], None
    env_seeds = os.environ.pop("GNSSACC_NB_SEEDS", None)
    try:
        t0 = time.perf_counter()
        nbclient.NotebookClient(
            nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(NB_DIR)}}
        ).execute()
        runtime = time.perf_counter() - t0
    finally:
        if env_seeds is not None:
            os.environ["GNSSACC_NB_SEEDS"] = env_seeds
    return nb, runtime


def _text(cell) -> str:
    return "".join(
        o.get("text", "") for o in cell.get("outputs", []) if o.get("output_type") == "stream"
    )


@pytest.mark.parametrize("name", NOTEBOOKS)
@pytest.mark.slow
def test_notebook_executes_and_answers(name):
    nb, runtime = _run(name)
    code = [c for c in nb.cells if c.cell_type == "code"]
    for c in code:
        assert not any(o.get("output_type") == "error" for o in c.get("outputs", [])), c.source[
            :200
        ]
    # Starts with the question, ends with the computed answer.
    assert nb.cells[0].cell_type == "markdown" and "Question" in nb.cells[0].source
    answer = _text(code[-1])
    assert len(answer.splitlines()) >= 4, answer
    assert "nan" not in answer.lower(), answer
    print(f"{name}: {runtime:.1f} s")


def test_acceleration_aiding_notebook_answers_from_the_stored_study():
    # The stored executed notebook (python notebooks/execute.py) read the study's rows: every
    # variant is counted over the cells, and the identity holds in both forms.
    nb = nbformat.read(NB_DIR / "acceleration_aiding.ipynb", as_version=4)
    answer = _text([c for c in nb.cells if c.cell_type == "code"][-1])
    assert "cloned = position-only" in answer and "joint = position-only" in answer, answer
    for variant in (
        "ekf-acc ",
        "ekf-accw ",
        "ekf-gm ",
        "smoother-acc ",
        "smoother-accw ",
        "smoother-gm ",
    ):
        assert variant in answer, (variant, answer)
    assert len(list((NB_DIR / "data" / "acceleration_aiding").glob("*.csv.gz"))) >= 1
    # ... and the velocity form's stored runs: the velocity updates against their floor, and each
    # velocity-derived acceleration against both baselines.
    assert "5. Doppler velocity" in answer and "knew the velocity exactly" in answer, answer
    for variant in ("ekf-vacc ", "ekf-vaccw ", "smoother-vacc ", "smoother-vaccw "):
        for base in ("(pos only)", "(pos+vel)"):
            assert f"{variant.strip():14s} vs {variant.split('-')[0]} {base}" in answer, answer
    assert (NB_DIR / "data" / "velocity_aiding" / "white.json").is_file()
