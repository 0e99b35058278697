"""minippo's benchmarks: runners that train sweeps and append CSV records (seven_tasks, table1, peers, speed, ...),
and one scoring module that turns the records into tables (scoring). Run each from the repository's root as a
module, e.g. ``python -m benchmarks.table1``; see benchmarks/README.md."""
