"""The answer, BUY / KEEP / TIE / UNDECIDED: found vs. baseline layouts compared on one draw (``compare``) and
on paired draws with confidence (``confidence``, its intervals from ``bootstrap``), raced until decided
(``racing``), and worded for the terminal, the report and the scripts (``words``). Every verdict name is imported
from these modules, never through another package (tests/test_structure.py).

See ARCHITECTURE.md for how the packages fit together."""
