"""``python -m geovs_drake.cli``: the ``geovs-drake`` command."""

from geovs_drake.cli import entry

entry()
