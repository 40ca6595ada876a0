"""Hydra configuration groups (shipped inside the package so installed scripts find them)."""
