"""Batches of cases (digital humans, robots, plants) on Ray: :mod:`sit2stand.batch.engine`."""
