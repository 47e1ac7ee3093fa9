import sys

from oricf.cli import main

sys.exit(main())
