"""`python -m vehid_cli` and the `vehid` console script run the command line."""

import signal


def main() -> None:
    """Import the command line and run it. Ctrl-C while Python imports it (about a second, before anything is
    read or written) ends the process quietly by the signal, not with an import traceback; from then on Ctrl-C
    is Python's KeyboardInterrupt, which the commands handle (identify and sweep keep their finished runs)."""
    previous = signal.getsignal(signal.SIGINT)
    if previous is not signal.SIG_IGN:  # started with Ctrl-C ignored (a background job): leave it so
        signal.signal(signal.SIGINT, signal.SIG_DFL)
    from .cli.app import run

    signal.signal(signal.SIGINT, previous)
    run()


if __name__ == "__main__":
    main()
