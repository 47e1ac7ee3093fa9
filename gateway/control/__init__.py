"""The control loop: a policy's chunks of actions played to a robot, one action a step.

Its core has no clock and no transport (the gateway runs it on the robot's clock, `oricf
bench control` on a simulator's steps):

    queue        each chunk's actions by the step they are for; late actions; counts
    merge        how actions two chunks give for one step are merged: one entry per mode
    loop         each tick: whether to ask the policy, the action or the safe one, the ages
    observation  the newest state messages and camera images as one observation
    parts        the observation's state parts and cameras, read through their types'
                 entries (oricf.gateway.topics.types)
    target       where the actions go, through bounds, rate and deadman

and the control input that runs it in a gateway (oricf.gateway.sources.control declares it):

    settings     the input's YAML (`input: {control: ...}`)
    ticks        when it ticks: on its own clock, or by the robot's state
    source       the loop, its observation and target together; its requests as the route's
                 items, told their answers (oricf.gateway.items.Asker)

It sits beneath the gateway's core (the core keeps a pipeline's loops by type, for its
/metrics) and imports only its own layer: `topics` (the robot's message types), `actuation`
(the deadman, a target's fields), `items`, `values` and `throttle`.
"""
