"""`common.files`: recursive search through linked folders, atomic writes."""

import os

from pushtoknow.common.files import find_files


def test_find_files_follows_linked_folders_once_and_sorts(tmp_path):
    data = tmp_path / "data"
    (data / "b").mkdir(parents=True)
    (data / "a.h5").write_text("")
    (data / "b" / "c.h5").write_text("")
    (data / "b" / "skip.json").write_text("")
    root = tmp_path / "root"
    root.mkdir()
    os.symlink(data, root / "linked")
    os.symlink(root, data / "b" / "loop")  # a cycle: each real folder is searched once
    found = find_files(root, "*.h5")
    assert found == [root / "linked" / "a.h5", root / "linked" / "b" / "c.h5"]
    assert find_files(root, "*.txt") == []


def test_atomic_writes_make_the_folders_they_need(tmp_path):
    """A report asked for in a folder that does not exist yet is written (`evaluate-real
    --markdown new/report.md` lost its work at the end before)."""
    from pushtoknow.common.files import atomic_write, atomic_write_set

    target = tmp_path / "new" / "deeper" / "report.md"
    assert atomic_write(target, "# report\n") == target
    assert target.read_text() == "# report\n"
    pair = {tmp_path / "a" / "x.json": "{}", tmp_path / "b" / "y.bin": b"\x00"}
    atomic_write_set(pair)
    assert [p.read_bytes() for p in pair] == [b"{}", b"\x00"]
    assert not list(tmp_path.rglob("*.tmp*"))
