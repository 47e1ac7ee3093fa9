"""Speech synthesis: `oricf serve tts`, text in and audio out (oricf.v1.SpeechSynthesizer and
OpenAI's POST /v1/audio/speech).

    config     configs/services/tts.yaml: the declared voices and the text limits
    text       the rule for what text is accepted, normalisation, sentences
    numbers    numbers as English words
    espeak     the espeak-ng program, run as a separate process (phonemes and speech)
    voices     what a voice engine is, and the registry of engines
    piper      Piper VITS voices on onnxruntime
    model      all declared voices, loaded once: text -> audio sentence by sentence
    servicer   the gRPC servicer; openai_api the HTTP route; service its ServiceParts
"""
