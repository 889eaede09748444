"""Progress bars stay short when the output is a log file, not a terminal."""

from __future__ import annotations

import io

import pytest

from handmesh_tutorial._progress import is_interactive, progress_bar


def _lines(text: str) -> list[str]:
    assert "\r" not in text, "a log gets whole lines, no carriage-return redraws"
    return [ln for ln in text.split("\n") if ln.strip()]


def test_a_job_prints_at_most_one_line_per_tenth():
    log = io.StringIO()
    for _ in progress_bar(range(1000), desc="generate", unit="sample", file=log):
        pass
    lines = _lines(log.getvalue())
    assert 1 <= len(lines) <= 10
    assert lines[-1].startswith("generate: 100%") and "1000/1000" in lines[-1]
    assert not any(" 0%" in ln for ln in lines), "no empty 0% line"


def test_an_epoch_prints_one_line_when_it_ends():
    log = io.StringIO()
    for epoch in range(3):
        for _ in progress_bar(range(169), desc=f"epoch {epoch + 1}/3", per="epoch", leave=False,
                              file=log):
            pass
    lines = _lines(log.getvalue())
    assert [ln.split(":")[0] for ln in lines] == ["epoch 1/3", "epoch 2/3", "epoch 3/3"]
    assert all("169/169" in ln for ln in lines)


def test_manual_bar_with_initial_counts_only_the_remaining_work():
    log = io.StringIO()
    bar = progress_bar(total=50, initial=20, desc="resume", file=log)
    for _ in range(30):
        bar.update()
    bar.close()
    lines = _lines(log.getvalue())
    assert len(lines) <= 10 and "50/50" in lines[-1]


def test_disabled_and_terminal_bars():
    log = io.StringIO()
    assert list(progress_bar(range(5), disable=True, file=log)) == list(range(5))
    assert log.getvalue() == ""
    assert not is_interactive(log)

    class Tty(io.StringIO):
        def isatty(self):
            return True

    tty = Tty()
    for _ in progress_bar(range(100), desc="tty", file=tty):
        pass
    assert "\r" in tty.getvalue(), "a terminal keeps tqdm's redrawing bar"


def test_per_is_checked():
    with pytest.raises(ValueError, match="per must be"):
        progress_bar(range(3), per="step", file=io.StringIO())


def test_default_stream_in_a_log_gets_whole_lines_not_redraws(capsys):
    # stderr captured by pytest is not a terminal and this is no Jupyter kernel: the default
    # stream must get the throttled lines (the bug: tqdm.auto's class was taken for a notebook's)
    for _ in progress_bar(range(200), desc="job"):
        pass
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = err.strip().splitlines()
    assert 1 <= len(lines) <= 11 and lines[-1].startswith("job: 100%"), lines
