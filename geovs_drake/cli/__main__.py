"""``python -m geovs_drake.cli``: the ``geovs-drake`` command."""

import sys

from geovs_drake.cli import main

sys.exit(main())
