"""The class grader behind ``minippo grade``: the chapters' tests, run against students' code in a worker process."""
