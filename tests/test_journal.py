"""The JSON-lines journal behind resumable runs: header checks, torn lines, restart, fingerprints."""

from __future__ import annotations

import json

import pytest

from dgse.errors import InputDataError
from dgse.journal import Journal, case_fingerprint, count_records
from tests.search import corridor_case


def test_nothing_is_written_before_the_first_piece(tmp_path):
    path = tmp_path / "sub" / "j.jsonl"
    with Journal(path, "search", {"seed": 1}) as j:
        assert j.records == []
    assert not path.exists() and count_records(path) == 0
    with Journal(path, "search", {"seed": 1}) as j:
        j.append({"k": 1, "x": [1.5, None]})
        j.append({"k": 2})
    header, *lines = path.read_text().splitlines()
    assert json.loads(header)["identity"] == {"seed": 1} and [json.loads(s)["k"] for s in lines] == [1, 2]
    with Journal(path, "search", {"seed": 1}) as j:  # resumed: the pieces come back as written
        assert j.records == [{"k": 1, "x": [1.5, None]}, {"k": 2}]
        j.append({"k": 3})
    assert count_records(path) == 3


def test_other_files_kinds_and_settings_are_refused(tmp_path):
    path = tmp_path / "j.jsonl"
    with Journal(path, "search", {"seed": 1, "method": "a"}) as j:
        j.append({"k": 1})
    with pytest.raises(InputDataError, match="'search' run, not of a 'evaluate' run"):
        Journal(path, "evaluate", {"seed": 1, "method": "a"})
    with pytest.raises(InputDataError, match=r'1 finished episode of a search run .*method was "a", now "b"'):
        Journal(path, "search", {"seed": 1, "method": "b"}, unit="episode")
    with pytest.raises(InputDataError, match=r"model \(not recorded\) is now"):
        Journal(path, "search", {"seed": 1, "method": "a", "model": "m"})
    other = tmp_path / "other.json"
    other.write_text('{"aggregate": {}}\n')
    with pytest.raises(InputDataError, match="not a dgse journal"):
        Journal(other, "search", {})
    # restart empties it at once; an empty or torn header is a fresh journal
    Journal(path, "search", {"seed": 2}, restart=True).close()
    assert count_records(path) == 0 and json.loads(path.read_text())["identity"] == {"seed": 2}
    path.write_text('{"format": "dgse-jou')
    with Journal(path, "search", {"seed": 3}) as j:
        assert j.records == []
        j.append({"k": 1})
    assert count_records(path) == 1


def test_torn_lines_are_dropped_and_the_file_mended(tmp_path):
    path = tmp_path / "j.jsonl"
    with Journal(path, "evaluate", {}) as j:
        for k in range(3):
            j.append({"k": k})
    path.write_text(path.read_text() + '{"k": 3, "x": [1, 2')  # killed while writing
    with Journal(path, "evaluate", {}) as j:
        assert [r["k"] for r in j.records] == [0, 1, 2]
        j.append({"k": 4})
    assert [json.loads(s)["k"] for s in path.read_text().splitlines()[1:]] == [0, 1, 2, 4]


def test_case_fingerprint():
    a = case_fingerprint(corridor_case())
    assert a == case_fingerprint(corridor_case()) and len(a) == 16
    assert a != case_fingerprint(corridor_case(source_cell=(5, 24)))
