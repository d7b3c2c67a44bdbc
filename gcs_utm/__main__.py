import sys

from gcs_utm.cli import main

sys.exit(main())
