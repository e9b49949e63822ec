"""Write ``tests/long_tests.txt``, the tests that the quick loop leaves out, from a run's
JUnit report: every test whose setup, call and teardown together took longer than
``--over`` seconds.

    .venv/bin/python -m pytest -m "" --junitxml=/tmp/run.xml
    .venv/bin/python scripts/long_tests.py /tmp/run.xml [--over 3.0]

``tests/conftest.py`` marks the listed tests ``long``; ``pytest -m "not slow and not long"`` is
the quick loop. A test missing from the list (new, renamed) runs in the quick loop until the list
is written again.
"""

from __future__ import annotations

import argparse
import xml.etree.ElementTree as ElementTree
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LIST = ROOT / "tests" / "long_tests.txt"


def node_id(classname: str, name: str) -> str:
    """pytest's node id of a JUnit test case: ``tests.core.test_x.TestY`` + ``test_z[a]`` ->
    ``tests/core/test_x.py::TestY::test_z[a]`` (the longest prefix that is a test file)."""
    parts = classname.split(".")
    for cut in range(len(parts), 0, -1):
        path = Path(*parts[:cut]).with_suffix(".py")
        if (ROOT / path).is_file():
            return "::".join([path.as_posix(), *parts[cut:], name])
    raise ValueError(f"no test file for {classname!r}")


def long_tests(report: Path, over: float) -> list[tuple[float, str]]:
    """(seconds, node id) of the report's tests over ``over`` seconds, longest first."""
    cases = ElementTree.parse(report).getroot().iter("testcase")
    timed = [(float(case.get("time", 0.0)), node_id(case.get("classname", ""), case.get("name", "")))
             for case in cases]
    return sorted((t for t in timed if t[0] > over), reverse=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("report", type=Path, help="a JUnit XML report (pytest --junitxml)")
    parser.add_argument("--over", type=float, default=3.0, help="seconds (default 3)")
    parser.add_argument("--note", default="", help="where and how the report was measured")
    args = parser.parse_args()
    chosen = long_tests(args.report, args.over)
    header = [f"# tests over {args.over:g} s in {args.report.name}"
              + (f" ({args.note})" if args.note else ""),
              "# written by scripts/long_tests.py; tests/conftest.py marks them 'long'"]
    LIST.write_text("\n".join(header + [node for _, node in chosen]) + "\n")
    print(f"{len(chosen)} tests over {args.over:g} s, {sum(t for t, _ in chosen):.0f} s in all: {LIST}")


if __name__ == "__main__":
    main()
