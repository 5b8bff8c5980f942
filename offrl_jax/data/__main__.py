"""`python -m offrl_jax.data list | info NAME | generate NAME`: the catalogue's command (catalogue.py)."""
from offrl_jax.data.catalogue import main
from offrl_jax.system.cli import run_main

run_main(main)
