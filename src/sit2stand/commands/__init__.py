"""The `sit2stand` sub-commands, by stage (:mod:`sit2stand.cli` puts them together)."""
