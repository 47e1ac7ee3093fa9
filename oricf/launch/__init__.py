"""Running a deployment: `oricf up` (its YAML, the plan, the launcher, health checks) and
`oricf certs` (its certificates and token)."""
