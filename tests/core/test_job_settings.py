"""A fit job's settings are checked against the engine's bounds before its input is read
(:func:`nurbs_core.jobs.settings.check_settings`, called by
:func:`nurbs_core.jobs.checks.check_before_work`)."""

from __future__ import annotations

import pytest

from nurbs_core.jobs import FitJob, fit_one
from nurbs_core.jobs.checks import check_before_work
from nurbs_core.jobs.settings import check_settings


@pytest.mark.parametrize("changes, message", [
    (dict(settings=["threads=10000"]), "threads must be at most"),
    (dict(settings=["samples_u=100000", "samples_v=100000"]), "more than the 4194304"),
    (dict(control_points=[3000, 3000]), "control_points_u must be at most 1000"),
    (dict(max_control_points=100000), "max_control_points must be at most 1000"),
    (dict(patches="100000"), "at most 2000 patches"),
    (dict(patches="2000", patch_size=40), "would take about"),
    (dict(patch_size=1000), "size must be an integer from 4 to 40"),
])
def test_a_setting_beyond_the_engines_bounds_is_refused_before_the_cloud_is_read(
        tmp_path, monkeypatch, changes, message):
    """--set threads=10000, samples or control grids beyond the engine's bounds were refused only
    after the cloud was read and its route decided; they now fail first, with the engine's
    message (the app takes the same bounds from FitConfig and PatchOptions)."""
    def never(*_args, **_kwargs):
        raise AssertionError("the cloud was read")

    monkeypatch.setattr("nurbs_core.io.load_points", never)
    job = FitJob(input=str(tmp_path / "scan.xyz"), output=[str(tmp_path / "fit.json")], **changes)
    with pytest.raises(ValueError, match=message):
        check_before_work(job)
    with pytest.raises(ValueError, match=message):  # a whole fit refuses it before reading
        fit_one(job)


@pytest.mark.parametrize("changes, line", [
    (dict(control_points=[3000, 3000]),
     "--control-points 3000 3000: control_points_u must be at most 1000, got 3000"),
    (dict(patches="2000", patch_size=40), "--patch-size 40: 2000 patches of 40 x 40"),
    (dict(patches="100000"), "--patches 100000: at most 2000 patches"),
    (dict(settings=["threads=10000"]), "threads must be at most"),     # --set named the field
])
def test_a_refusal_names_the_option_the_user_gave(changes, line):
    with pytest.raises(ValueError) as refused:
        check_settings(FitJob(input="a.xyz", **changes))
    assert str(refused.value).startswith(line)


def test_settings_within_the_bounds_pass():
    for job in (FitJob(input="a.xyz"), FitJob(input="a.xyz", patches="100", patch_size=16),
                FitJob(input="a.xyz", curve=True, samples=[100000]),
                FitJob(input="a.xyz", settings=["threads=2"])):
        check_settings(job)


def _sheet(count: int = 900):
    import numpy as np

    rng = np.random.default_rng(2)
    xy = rng.uniform(-1.0, 1.0, (count, 2))
    return np.column_stack([xy, 0.2 * np.sin(xy[:, 0]) * np.cos(xy[:, 1])])


def _ring(count: int = 200):
    import numpy as np

    angle = np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    return np.column_stack([2.0 * np.cos(angle), np.sin(angle), np.zeros(count)])


@pytest.mark.parametrize("cloud, changes", [
    (_sheet, dict(single_patch=True)),
    (_sheet, dict(trim=True)),
    (_ring, dict(curve=True)),
    (_ring, dict()),                     # the automatic route, which finds a curve
])
def test_a_fit_checks_its_job_once(tmp_path, monkeypatch, cloud, changes):
    """fit_one checked the job, then prepare_fit (the forced single patch, the automatic route's
    curve) or fit_trimmed_job (--trim) checked it again: one place checks now."""
    import numpy as np

    from nurbs_core.jobs import checks

    calls = []

    def counted(job):
        calls.append(job)
        return checks.check_before_work(job)

    monkeypatch.setattr("nurbs_core.jobs.one_input.check_before_work", counted)
    monkeypatch.setattr("nurbs_core.jobs.single.check_before_work", counted)
    source, out = tmp_path / "scan.xyz", tmp_path / "fit.json"
    np.savetxt(source, cloud())
    fit_one(FitJob(input=str(source), output=[str(out)], iterations=20, quiet=True, **changes))
    assert out.exists() and len(calls) == 1


def test_a_solid_output_of_a_cloud_the_automatic_route_fits_as_a_curve_is_refused_first(
        tmp_path):
    """The automatic route's curve was refused a .brep output by the second check of its job
    (then with "unknown suffix"); with one check it is refused as every route that makes no
    solid is, before the curve is fitted, and nothing is written."""
    import numpy as np

    from nurbs_core.io.errors import FileFormatError

    source, out = tmp_path / "ring.xyz", tmp_path / "ring.brep"
    np.savetxt(source, _ring())
    with pytest.raises(FileFormatError, match="holds a solid, but the scan is not fitted as one"):
        fit_one(FitJob(input=str(source), output=[str(out)], quiet=True))
    assert list(tmp_path.iterdir()) == [source]
