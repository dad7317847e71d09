from eelhost.cli import main


def test_vision_bench_prints_and_writes_figures_layout_and_calibration_howto(tmp_path, capsys):
    out = tmp_path / "vision.md"
    assert main(["vision-bench", "--frames", "4", "--write", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "centre-of-mass error, rms" in printed and "frames/s" in printed
    text = out.read_text()
    for part in ("## Marker layout", "### Printing", "## Calibration", "heading error, rms",
                 "localisation only", "one core"):
        assert part in text


def test_vision_bench_without_write_prints_and_leaves_the_folder_alone(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["vision-bench", "--frames", "2"]) == 0
    assert "centre-of-mass error, rms" in capsys.readouterr().out
    assert list(tmp_path.iterdir()) == []  # no docs/vision.md in the user's folder
