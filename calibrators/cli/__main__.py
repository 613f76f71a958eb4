import sys

try:
    from calibrators.cli import main
except KeyboardInterrupt:
    # Ctrl-C while the command line itself loads: one line and SIGINT's status, as main
    # gives once it runs.
    print("orthoglide: interrupted", file=sys.stderr)
    sys.exit(130)

sys.exit(main())
