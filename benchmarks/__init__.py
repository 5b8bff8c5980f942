from offrl_jax.system.interrupts import quiet_start as _quiet_start

_quiet_start()  # only when one of this package's modules runs as a command (`python -m`): system.interrupts
