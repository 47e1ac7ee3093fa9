"""How a fact travels in GenerateRequest.context, between whoever produces it (the gateway's
data products) and the language service that renders it into a prompt:

    people_count: "3"            the value
    people_count_age_s: "1.2"    its age in seconds
    people_count_stale: "true"   the producer knows it is out of date
"""

AGE_SUFFIX = "_age_s"
STALE_SUFFIX = "_stale"
