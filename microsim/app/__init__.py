"""The application around runs: the session (the one front door of the command line and of
Python), parameter sweeps, and the progress line."""
