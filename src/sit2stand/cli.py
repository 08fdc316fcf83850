"""The `sit2stand` command (placeholder)."""
def main() -> int:
    return 0
