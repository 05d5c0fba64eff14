"""Regenerative chatter: a tool's tip dynamics (modes or a measured FRF), stability lobes by
the zero-order approximation and by semi-discretisation, the regenerative time-domain model,
the stability margin of a program's cuts, and modal fits to a tap test (docs/chatter.md)."""
