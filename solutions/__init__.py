"""Reference solutions of the exercises, one module per chapter, with the same functions as exercises/.

The grading tests check them by default (``pytest``); ``minippo grade --solutions`` shows their scoreboard.
"""
