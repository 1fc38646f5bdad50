"""What runs a procedure and tells of it: the runner and its sinks, the events, run control (pause,
abort), states and the input errors every layer raises.
"""
