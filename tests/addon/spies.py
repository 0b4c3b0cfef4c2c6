"""Spies shared by the add-on tests (no pytest fixtures here)."""

import hemishadow


def count_solves(monkeypatch):
    """A list that gets one item per TransferSolver.solve call from now on (for this test)."""
    calls = []
    original = hemishadow.TransferSolver.solve

    def solve(self, *args, **kwargs):
        calls.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(hemishadow.TransferSolver, "solve", solve)
    return calls
