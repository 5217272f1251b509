"""The batch job file: a malformed one fails before anything runs, naming the line and the field."""

from __future__ import annotations

import pytest

from workbench.batch import JobFileError, load_jobs, parse_jobs

GOOD = """\
output = "out"
[[characters]]
name = "head"
rig = "head.fwb"
[[takes]]
name = "take1"
path = "take1.csv"
[[steps]]
kind = "export"
formats = ["glb", "usdc"]
"""


@pytest.fixture
def project(tmp_path):
    (tmp_path / "head.fwb").write_bytes(b"not read by the checker")
    (tmp_path / "take1.csv").write_text("time,jawOpen\n0,0\n")
    return tmp_path


def _check(project, text):
    path = project / "jobs.toml"
    path.write_text(text)
    return load_jobs(path)


def test_the_minimal_job_file_of_the_issue(project):
    jobs = _check(project, GOOD)
    assert jobs.output == (project / "out").resolve()
    assert [c.name for c in jobs.characters] == ["head"]
    assert jobs.characters[0].rig == (project / "head.fwb").resolve()
    assert jobs.takes[0].path == (project / "take1.csv").resolve()
    assert [(s.kind, s.options) for s in jobs.steps] == [("export", {"formats": ["glb", "usdc"]})]
    assert jobs.n_tasks == 1


def _error(project, text) -> str:
    with pytest.raises(JobFileError) as info:
        _check(project, text)
    return str(info.value)


def test_unknown_step_kind_names_line_and_value(project):
    msg = _error(project, GOOD.replace('kind = "export"', 'kind = "exprot"'))
    assert msg.startswith('jobs.toml line 9: [[steps]] kind = "exprot": expected one of ')
    assert "export" in msg and "track" in msg


def test_syntax_error_names_the_line(project):
    msg = _error(project, GOOD.replace('name = "take1"', 'name = "take1'))
    assert msg.startswith("jobs.toml line 6: TOML syntax error")


@pytest.mark.parametrize(
    ("change", "line", "needle"),
    [
        (('rig = "head.fwb"', 'rig = "missing.fwb"'), 4, '[[characters]] rig = "missing.fwb": no such file'),
        (('path = "take1.csv"', 'path = "take1.csv"\ncolour = "red"'), 8, "[[takes]] colour = \"red\": unknown field 'colour'"),
        (('formats = ["glb", "usdc"]', 'formats = "glb"'), 10, '[[steps]] formats = "glb": expected an array, got a string'),
        (('formats = ["glb", "usdc"]', 'formats = ["glb", "docx"]'), 10, "unknown format 'docx'"),
        (('output = "out"', 'output = 3'), 1, "output = 3: expected a string"),
        (('output = "out"', 'output = "out"\nworkers = 4'), 2, "workers = 4: unknown field 'workers'"),
        (('name = "head"\n', ''), 2, "[[characters]]: missing field 'name'"),
        (('name = "take1"', 'name = "take 1"'), 6, 'name = "take 1": names are letters'),
    ],
)
def test_schema_errors_name_line_and_field(project, change, line, needle):
    msg = _error(project, GOOD.replace(*change))
    assert msg.startswith(f"jobs.toml line {line}: "), msg
    assert needle in msg, msg


def test_step_fields_are_checked_per_kind(project):
    (project / "db.csv").write_text("time,jawOpen\n0,0\n")
    text = GOOD + '[[steps]]\nkind = "retime"\nt0 = 0.5\nt1 = "end"\ndatabase = ["db.csv"]\n'
    msg = _error(project, text)
    assert msg.startswith('jobs.toml line 14: [[steps]] t1 = "end": expected an integer or a number'), msg
    text = GOOD + '[[steps]]\nkind = "retime"\nt0 = 0.5\ndatabase = ["db.csv"]\n'
    assert "line 11: [[steps]]: missing field 't1'" in _error(project, text)
    text = GOOD + '[[steps]]\nkind = "retime"\nt0 = 0.5\nt1 = 1.0\ndatabase = ["db.csv"]\nmethod = "nearest"\n'
    assert "method" in (msg := _error(project, text)) and "expected auto, closest or take" in msg, msg
    text = GOOD + '[[steps]]\nkind = "retime"\nt0 = 0.5\nt1 = 1.0\ndatabase = ["db.csv"]\nmethod = "take"\n'
    assert parse_jobs(text, project / "jobs.toml").steps[-1].options["method"] == "take"


def test_track_needs_a_marker_map(project):
    text = GOOD.replace('kind = "export"\nformats = ["glb", "usdc"]', 'kind = "track"')
    msg = _error(project, text)
    assert msg.startswith("jobs.toml line 5: [[takes]]: a track step needs a vertex_map"), msg


def test_a_missing_job_file_and_parse_from_text(tmp_path, project):
    with pytest.raises(JobFileError, match="cannot read the job file"):
        load_jobs(tmp_path / "nope.toml")
    assert parse_jobs(GOOD, project / "jobs.toml").n_tasks == 1


def test_importing_workbench_does_not_import_dask():
    import subprocess
    import sys

    code = ("import sys, workbench, workbench.batch; "
            "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed')); "
            "print(bad); sys.exit(1 if bad else 0)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_a_clone_step_needs_an_existing_face(project):
    text = GOOD + '[[steps]]\nkind = "clone"\nonto = "nowhere.obj"\n'
    msg = _error(project, text)
    assert "onto" in msg and "nowhere.obj" in msg, msg
    (project / "other.obj").write_text("v 0 0 0\n")
    step = parse_jobs(GOOD + '[[steps]]\nkind = "clone"\nonto = "other.obj"\n', project / "jobs.toml").steps[-1]
    assert step.kind == "clone" and step.options["onto"] == str(project / "other.obj")
