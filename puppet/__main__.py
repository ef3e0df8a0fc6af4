import sys

from puppet.cli import main

if __name__ == "__main__":  # not when a spawned worker process (batch) re-imports the main module
    sys.exit(main())
