"""The exercises, one module per chapter: write each function whose body raises NotImplementedError.

Each function's docstring is its contract (shapes, dtypes, the equation, the gradient to return). Grade a chapter with
``minippo grade 5`` (or all of them with ``minippo grade``); exercises/README.md explains the rest.
"""
