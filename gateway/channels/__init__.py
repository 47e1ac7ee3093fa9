"""Text channels: the line-based TCP server that text inputs and outputs name (`server`:
admission, timeouts, tokens) and one connected client (`clients`: its writes, the answers it
waits for). Imports nothing else of the gateway.
"""
