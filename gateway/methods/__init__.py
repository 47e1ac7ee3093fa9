"""The methods a route can call, one module each: its call schema, its request, its typed
result, its class (an oricf.gateway.components.MethodCall, built once per route, `execute`
per record, `close`), and its declaration `METHOD = Method(...)`
(oricf.gateway.components.Method), listed in COMPONENTS below, from which
oricf.gateway.components.METHODS loads them and the pipeline schema's `call:` union is
built (oricf.gateway.config.CallConfig).

    Detect      image            -> Detections (detections)
    Transcribe  audio            -> Transcript (transcript, duration_s); no words ends the route
    Generate    prompt template  -> Answer (answer); data products as typed facts for context
    Infer       image            -> Detections, or Classes (classes, label, score)
    Synthesize  text template    -> Speech (speech: each sentence's audio as it is made; spoken)
    Act         observation      -> Actions (actions, start_step, observation_step)

Adding a method is one module here with its class and METHOD, its line in COMPONENTS,
and its test in tests/gateway/methods/.
The modules beside them (base, chat, sentences, infer_shared) are what methods share.
"""

COMPONENTS = (
    "act",
    "detect",
    "generate",
    "infer",
    "synthesize",
    "transcribe",
)
