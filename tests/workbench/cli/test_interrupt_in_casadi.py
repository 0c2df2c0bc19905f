"""A signal that arrives inside a CasADi call comes out of it as CasADi's own error (its SWIG
wrapper turns the ``KeyboardInterrupt`` into ``NotImplementedError: Wrong number or type of
arguments for function 'Function_call'``). A user who pressed Ctrl-C about 2 s into a
``--resume`` read those words as the command's end; it is told as the interrupt it was."""

from __future__ import annotations

import importlib
import os
import signal

cli_main = importlib.import_module("ddvp_nlp.cli.main")  # the module; `cli.main` is its function

CASADI_WORDS = ("Wrong number or type of arguments for function 'Function_call'.\n"
                "  Possible prototypes are:\n    call(self,dict:DM,bool,bool)")


def _swallowing(request):
    """A command whose CasADi call swallows the interrupt, as CasADi does."""
    try:
        os.kill(os.getpid(), signal.SIGINT)  # the handler raises at the next instruction
        for _ in range(10_000_000):  # until it has (a count, not a time)
            pass
    except KeyboardInterrupt:
        raise NotImplementedError(CASADI_WORDS) from None
    return 0


def test_an_interrupt_casadi_reports_as_its_error_is_told_as_the_interrupt(
        monkeypatch, capsys, tmp_path):
    monkeypatch.setattr(cli_main, "command", lambda name: _swallowing)
    code = cli_main.main(["march", "harmonic", "--no-plot", "--out", str(tmp_path / "run")])
    err = capsys.readouterr().err
    assert code == 1
    assert "interrupted (SIGINT) inside a compiled call (which ended with " \
           "NotImplementedError); every file written before it is whole" in err
    assert "Function_call" not in err and "Possible prototypes" not in err
