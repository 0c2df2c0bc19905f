"""Built-in scenes of ddvp_nlp: one file each, installed as ``ddvp_nlp.problems``."""
