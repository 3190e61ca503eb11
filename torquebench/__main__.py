import sys

from torquebench.cli import main

sys.exit(main())
