"""What runs a procedure and tells of it: the runner and its sinks, the event base and the run's
lifecycle events, run control (pause, abort). Each procedure package owns its own events and
payloads; the words every layer shares (input errors, outcomes) are procedures/vocabulary.py.
"""
