"""What a file says is checked like the command line (issue 39): a run folder is data, never
code or authority (``--resume`` rebuilds the system from the scene the user names, checked
against the fingerprint the run kept); a folder being written is busy for readers too; default
folder names carry every input that changes the result; grid rows are reused only when the
manifest vouches for their file; ``--cluster FILE`` is read like any file the user names."""

from ddvp_nlp.cli import main

HARMONIC = """from ddvp_nlp import Scene
def H(q, p, t):
    return p[0]**2/2 + {k}*q[0]**2/2
scene = Scene(H, n=1, q0=[1.0], p0=[0.0], tau0=0.1, t_end=2)
"""


def test_periodic_of_a_scene_whose_energy_is_nowhere_finite_on_the_ray_says_so(tmp_path,
                                                                                capsys):
    """H = p^2/2 - 1/q^2 on the section q1 = 0 is infinite along the whole start ray: the
    message had been numpy's 'zero-size array to reduction operation minimum'."""
    scene = tmp_path / "singular.py"
    scene.write_text("from ddvp_nlp import Scene\ndef H(q, p, t):\n    return p[0]**2/2 - "
                     "1/q[0]**2\nscene = Scene(H, n=1, q0=[1.0], p0=[0.5], tau0=0.01, "
                     "t_end=1)\n")
    code = main(["periodic", str(scene), "--energy", "0.5", "--nodes", "20", "--section",
                 "q1=0", "--no-plot", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 2, err
    assert "H is not finite anywhere on the start's ray of the section q1=0" in err
    assert "zero-size" not in err and "Traceback" not in err
