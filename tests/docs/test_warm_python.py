"""The warm interpreter that runs the docs' pages and the examples (tests/helpers/forked.py)
gives each job a process of its own: what one job changes (a module's globals, the environment,
its folder) the next never sees, so no page can depend on another; a failure is its exit code
and its traceback, a script's exit code is its own, and a job reads no input."""


def test_a_job_leaves_nothing_to_the_next(warm_python, tmp_path):
    first, second = tmp_path / "first", tmp_path / "second"
    first.mkdir()
    second.mkdir()
    changes = [(1, "import os, ddvp_nlp, numpy\n"
                   "ddvp_nlp.LEFT_BY_A_PAGE = 1\n"
                   "numpy.set_printoptions(precision=2)\n"
                   "os.environ['LEFT_BY_A_PAGE'] = '1'\n"
                   "open('left.txt', 'w').write('x')\n"
                   "print('first', os.getcwd())\n")]
    assert warm_python.run("blocks", first, cpu=60, blocks=changes) == (
        0, f"first {first}\n", "")
    looks = [(1, "import os, ddvp_nlp, numpy\n"
                 "print(hasattr(ddvp_nlp, 'LEFT_BY_A_PAGE'), 'LEFT_BY_A_PAGE' in os.environ,\n"
                 "      numpy.get_printoptions()['precision'], os.listdir('.'), os.getcwd())\n")]
    assert warm_python.run("blocks", second, cpu=60, blocks=looks) == (
        0, f"False False 8 [] {second}\n", "")
    assert (first / "left.txt").read_text() == "x"


def test_a_failure_is_an_exit_code_with_its_traceback(warm_python, tmp_path):
    code, out, _ = warm_python.run("blocks", tmp_path, cpu=60,
                                   blocks=[(3, "print('before')"), (7, "1 / 0")])
    assert code == 1 and out.startswith("before\nthe block at line 7 failed:")
    assert "ZeroDivisionError" in out
    script = tmp_path / "script.py"
    script.write_text("import sys\nprint(sys.argv[0] == __file__, __name__, sys.stdin.read()"
                      " == '')\nsys.exit(3)\n")
    assert warm_python.run("script", tmp_path, cpu=60, path=str(script)) == (
        3, "True __main__ True\n", "")
    script.write_text("raise ValueError('from a script')\n")
    code, out, err = warm_python.run("script", tmp_path, cpu=60, path=str(script))
    assert code == 1 and out == "" and "ValueError: from a script" in err
