"""``python -m optplan ...``: the ``optplan`` command (:func:`optplan._entry.main`)."""
import sys

from ._entry import main

sys.exit(main())
