import sys

from safenav.cli import main

sys.exit(main())
