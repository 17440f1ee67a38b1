import sys

from gpr3d.cli.main import main

sys.exit(main())
