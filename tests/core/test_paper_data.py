"""The paper's data set is found by the environment variable or beside a checkout, never by a
machine path written in the code."""

from __future__ import annotations

from pathlib import Path

import pytest

from nurbs_core.paper_data import DATA_VARIABLE, paper_data_dir


def test_the_variable_names_the_folder_and_a_missing_folder_gives_none(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    (tmp_path / "elsewhere" / "nurbsdiff_paper").mkdir(parents=True)
    monkeypatch.setenv(DATA_VARIABLE, str(tmp_path / "elsewhere"))
    assert paper_data_dir(tmp_path / "nowhere") == tmp_path / "elsewhere" / "nurbsdiff_paper"
    monkeypatch.delenv(DATA_VARIABLE)
    assert paper_data_dir(tmp_path / "nowhere") is None


def test_a_checkout_beside_shared_data_finds_it(tmp_path: Path,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(DATA_VARIABLE, raising=False)
    (tmp_path / "shared" / "data" / "nurbsdiff_paper").mkdir(parents=True)
    checkout = tmp_path / "main" / "tests"
    checkout.mkdir(parents=True)
    assert paper_data_dir(checkout) == (tmp_path / "shared" / "data" / "nurbsdiff_paper").resolve()
