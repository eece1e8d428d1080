"""The evaluation's scenes, made by one command with a sub-command per kind (`python -m
relocation_app.evaluation.scenes KIND ...`, also `./run evaluate scenes KIND ...`; cli.py): `generated` (this
project's geometry: scenario1_5, scenario2_10, random5/), `paper N` (scenes of the paper's size, searched with the
real planner), `paper-random` (Table 4's random cases at the paper's size) and `jitter` (perturbed copies of a shipped
scene). What the kinds do alike is in layout.py (drawing bottles, writing the scenario file with its header) and
screening.py (judging a layout: lane screen, real-planner tree, one optimum, perception's view); each kind's own
rules in its module (generated.py, paper_size.py, paper_random.py, jitter.py); complete_tree.py counts a scene's
complete Q-Tree."""
