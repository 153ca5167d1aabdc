"""`common.files.find_files`: recursive search through linked folders."""

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
