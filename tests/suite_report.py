"""A suite's measurement report: lines printed as the tests run, repeated in pytest's terminal
summary (unless already shown with -s) and written to ``OUT/report.md``."""

from __future__ import annotations

from pathlib import Path


class SuiteReport:
    def __init__(self, title: str, out_dir: Path):
        self.title = title
        self.out_dir = out_dir
        self.lines: list[str] = []

    def line(self, text: str = "") -> None:
        self.lines.append(text)
        print(text)

    def terminal_summary(self, terminalreporter, config) -> None:
        """Call from the suite's ``pytest_terminal_summary`` hook."""
        if not self.lines:
            return
        if config.option.capture != "no":  # with -s they were printed already
            terminalreporter.section(self.title)
            for line in self.lines:
                terminalreporter.write_line(line)
        self.out_dir.mkdir(parents=True, exist_ok=True)
        (self.out_dir / "report.md").write_text("\n".join(self.lines) + "\n")
