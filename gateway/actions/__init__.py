"""What a control loop does with a policy's chunks of actions: one action per step, queued by
the step it is for, the chunks that overlap merged (`queue`). Imports nothing else of the
gateway.
"""
