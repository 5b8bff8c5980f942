"""The application: what a `python -m experiments.<name>` command does with a study, step by step.

    command.py   `run_command`: read the command, start the processes, claim the output, load the data, check a
                 resume, run, clean up (one named step each)
    outputs.py   a run's directory: where a new run writes, what --overwrite may replace, the saved studies
    studies.py   what the MuJoCo studies share: their flags, the variants a command line asks for, the study
    flags.py     the run flags, and one flag per config field of every registered family
    launch.py    where the training runs: this process's CPU cores, a multi-process run's other processes
"""
