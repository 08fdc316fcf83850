"""``python -m sit2stand.bench``: the speed figures (:mod:`sit2stand.bench.speed`, ``make bench``)."""

import sys

from .speed import main

sys.exit(main())
