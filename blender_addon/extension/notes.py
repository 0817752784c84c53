"""Collects what the translation could not carry over, so each thing is reported once."""

from __future__ import annotations


class Notes:
    """Unsupported features and approximations met while translating a scene.

    ``unsupported`` lines are things Petzval ignores or replaces (shown as one WARNING report
    after the render); ``info`` lines are approximations worth knowing (printed to the console and
    shown in the same report). Each distinct line is kept once, in the order first met.
    """

    def __init__(self) -> None:
        self.unsupported: list[str] = []
        self.info: list[str] = []
        self._seen: set[str] = set()

    def warn(self, text: str) -> None:
        if text not in self._seen:
            self._seen.add(text)
            self.unsupported.append(text)

    def note(self, text: str) -> None:
        if text not in self._seen:
            self._seen.add(text)
            self.info.append(text)

    def summary(self) -> str:
        """One line listing everything (empty when there is nothing to say)."""
        parts = []
        if self.unsupported:
            parts.append(
                f"not supported, ignored or replaced ({len(self.unsupported)}): " + "; ".join(self.unsupported)
            )
        if self.info:
            parts.append("approximations: " + "; ".join(self.info))
        return " | ".join(parts)
