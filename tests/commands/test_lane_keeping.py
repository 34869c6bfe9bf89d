"""sims/commands/lane_keeping.py (the picture of docs/guides/beyond_nav2.md): its option checks, one line and
exit code 2, before any simulation. The run itself is the guide's figure (about 3 minutes), not a test."""

import pytest

from sims.commands import lane_keeping


@pytest.mark.parametrize(("argv", "match"), [
    (["--robots", "1"], "--robots: must lie in [2, 16]; got 1"),
    (["--seconds", "6_0"], "--seconds: invalid int value"),
    (["--cost-weight", "nan"], "--cost-weight: must lie in [0, 100]"),
    (["--cost-weight", "-1"], "--cost-weight: must lie in [0, 100]"),
    (["--out", "pic.jpg"], "--out: must name a .png file"),
    (["--out", ""], "--out: must name a path"),
])
def test_bad_options_are_one_line_and_exit_2(argv, match, capsys, tmp_path, monkeypatch):
  monkeypatch.chdir(tmp_path)
  with pytest.raises(SystemExit) as e:
    lane_keeping.main(argv)
  assert e.value.code == 2
  err = capsys.readouterr().err
  assert err.count("\n") == 1 and match in err, err


def test_a_folder_is_not_a_picture_path(capsys, tmp_path):
  (tmp_path / "x.png").mkdir()
  with pytest.raises(SystemExit) as e:
    lane_keeping.main(["--out", str(tmp_path / "x.png")])
  assert e.value.code == 2 and "not a folder" in capsys.readouterr().err
