"""What people look at: ``report.html`` (self-contained) and ``report.md`` for a result folder
(:func:`optipose.report.build.write_report`), built from one module per section, and pictures of a part
with its sensors (:mod:`optipose.report.views`).

See ARCHITECTURE.md for how the packages fit together."""
