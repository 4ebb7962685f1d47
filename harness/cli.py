"""Command-line interface `mbh`."""

def main():
    raise SystemExit("not yet")
