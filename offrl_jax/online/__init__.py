"""The pieces of the online phase (fine-tuning in the environment after the offline phases), each small and pure
where it can be: `buffer` (per-member online replay as fixed-capacity device arrays), `returns` (Monte-Carlo returns
of the episodes it collects), `sampling` (minibatches from the offline data and a member's buffer, inside jit),
`envs` (one gymnasium env per member on the host, and the collector of blocks of transitions).  docs/online.md says
how they compose into a phase of the driver.
"""
