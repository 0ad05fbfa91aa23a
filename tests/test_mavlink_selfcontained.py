"""The flight-log tests need nothing outside the repository (issue 16).

Every flight-log test module (``_flightlogs.LOG_TESTS``) runs in this suite under an audit hook
(``_flightlogs.log_guard``, installed by tests/conftest.py) that makes every attempt to open a file named
like a flight log outside the repository fail, a ``../shared`` beside it included. On top of that, a copy of
the repository's packages and tests is made in a temporary folder (so there is no ``../shared`` beside it)
and the log readers' tests (every log through mission_sim's readers and pymavlink, the ULog) run there in a
separate process, under the same hook refusing the repository itself: they pass, the logs come from
``tests/data/flightlogs``. (The suite itself runs the rest of ``LOG_TESTS`` under the guard: the copy does
not run them a second time.)

The copy takes numba's cache files of the repository along (with the sources' modification times,
numba's cache key), so the inner run loads the kernels the outer suite compiled instead of compiling
them again (a cache miss only costs time). Its result is read from its JUnit XML report and exit code,
not by searching its output for words (a test's name may contain "failed").
"""

import os
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from _flightlogs import DATA_DIR, LOG_NAMES, LOG_TESTS, ULOG_NAME, log_guard

ROOT = Path(__file__).resolve().parents[1]
#: what the copy runs: every log read by the project's readers and by pymavlink, and the ULog
IN_THE_COPY = ("test_mavlink_io.py", "test_mavlink_ulog.py")
GUARD = """
import sys
from pathlib import Path
from _flightlogs import log_guard
sys.addaudithook(log_guard(Path(__file__).resolve().parents[1], Path({repo!r})))
"""


def _only_numba_caches(ignore):
    """``copytree``'s ignore: ``ignore``'s names, and in ``__pycache__`` every file but numba's cache
    (``.nbi`` index, ``.nbc`` data, the ``.deps`` stamp of :mod:`wpt_receiver.kernel_cache`)."""
    def names(folder, entries):
        if Path(folder).name == "__pycache__":
            return {e for e in entries if Path(e).suffix not in (".nbi", ".nbc", ".deps")}
        return set(ignore(folder, entries))
    return names


def _junit_counts(path: Path) -> dict[str, int]:
    """tests / failures / errors / skipped summed over the test suites of a pytest JUnit XML report."""
    root = ET.parse(path).getroot()
    suites = [root] if root.tag == "testsuite" else root.findall("testsuite")
    return {k: sum(int(s.get(k, 0)) for s in suites) for k in ("tests", "failures", "errors", "skipped")}


def test_every_log_test_is_run_without_shared():
    readers = {p.name for p in (ROOT / "tests").glob("test_*.py")
               if "_flightlogs" in p.read_text() and "fuzz" not in p.name and p.name != Path(__file__).name}
    assert readers <= set(LOG_TESTS), sorted(readers - set(LOG_TESTS))


def test_logs_are_in_the_repository():
    for name in (*LOG_NAMES, ULOG_NAME, "SOURCES.md"):
        assert (DATA_DIR / name).is_file(), name
        assert DATA_DIR in (DATA_DIR / name).resolve().parents
    assert "../shared" not in (ROOT / "tests" / "_flightlogs.py").read_text()
    sizes = sum((DATA_DIR / n).stat().st_size for n in (*LOG_NAMES, ULOG_NAME))
    assert sizes < 4e6                     # a few MB in the repository, not the 9 MB originals


def test_the_guard_refuses_logs_outside_the_repository(tmp_path):
    hook = log_guard(ROOT, ROOT.parent / "shared")
    for bad in (ROOT.parent / "shared" / "flightlogs" / LOG_NAMES[0], Path("/srv") / ULOG_NAME,
                Path("/srv/SOURCES.md")):
        with pytest.raises(PermissionError, match="outside the repository"):
            hook("open", (str(bad), "r", 0))
    for good in (DATA_DIR / LOG_NAMES[1], tmp_path / LOG_NAMES[0], Path("/srv/notes.txt")):
        hook("open", (str(good), "r", 0))
    log_guard(ROOT, ROOT.parent / "shared", active=lambda: False)("open", (str(Path("/srv") / ULOG_NAME), "r", 0))


def test_log_tests_pass_in_a_copy_without_shared(tmp_path):
    assert set(IN_THE_COPY) <= set(LOG_TESTS)
    clone = tmp_path / "clone"
    ignore = shutil.ignore_patterns("*.pyc", ".hypothesis")
    for pkg in ("wpt_receiver", "mission_sim", "envs", "policies", "tests"):
        shutil.copytree(ROOT / pkg, clone / pkg, ignore=_only_numba_caches(ignore))   # copy2: mtimes kept
    (clone / "tests" / "_no_shared.py").write_text(GUARD.replace("{repo!r}", repr(str(ROOT))))
    assert not (tmp_path / "shared").exists()
    env = {**os.environ, "PYTHONPATH": f"{clone}{os.pathsep}{clone / 'tests'}", "OMP_NUM_THREADS": "1"}
    for k in [k for k in env if k.startswith("PYTEST_")] + ["DRONEWPT_FLIGHTLOGS"]:   # no outer xdist/addopts state
        env.pop(k, None)
    report = tmp_path / "inner.xml"
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", "-p", "_no_shared",
                        f"--junitxml={report}", *(f"tests/{name}" for name in IN_THE_COPY)],
                       cwd=clone, env=env, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    counts = _junit_counts(report)
    assert counts["failures"] == counts["errors"] == counts["skipped"] == 0 and counts["tests"] >= len(LOG_NAMES), counts
    # the guard works: the same hook refuses the repository's own copy (outside the clone)
    probe = subprocess.run([sys.executable, "-c", f"import _no_shared; open({str(DATA_DIR / 'SOURCES.md')!r})"],
                           cwd=clone, env=env, capture_output=True, text=True, timeout=60)
    assert probe.returncode != 0 and "outside the repository" in probe.stderr
