"""The answer: found vs. baseline layouts compared on one draw (``compare``) and on paired draws with
confidence (``confidence``), raced until decided (``racing``), and worded for the terminal, the report and the
tables (``words``).

See ARCHITECTURE.md for how the packages fit together."""
