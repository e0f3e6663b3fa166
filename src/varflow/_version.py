"""The version of varflow, single-sourced (``pyproject.toml`` reads it from here).

It is bumped whenever the default results change (a default parameter, a kernel's
arithmetic): :mod:`varflow.batch` refuses to resume an output folder made by
another version, so a folder never mixes the results of two versions.
"""

__version__ = "0.9.1"
