"""Result folders: writing them as a run goes (:mod:`optipose.io.folders`, :mod:`optipose.io.evaluation`,
:mod:`optipose.io.search`), the one place that turns records into tables (:mod:`optipose.io.tables`),
and reading them back (:func:`load_result`: the results of :mod:`optipose.io.results`, each folder's
``config.toml`` read once as a :class:`~optipose.io.config.RunConfig`)."""


def load_result(folder):
    """The typed result in a result folder (see :mod:`optipose.io.load`)."""
    from optipose.io.load import load_result as _load

    return _load(folder)


__all__ = ["load_result"]
