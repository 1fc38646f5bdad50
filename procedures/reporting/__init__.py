"""What a session becomes on paper: the ISO 230-2 evaluation, its test report, the session report."""
