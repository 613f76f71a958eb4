import sys

from calibrators.cli import main

sys.exit(main())
