"""Regenerate the default-machine block of docs/configuration.md from the schema.

    python3 docs/gen_configuration.py

(tests/test_simulate_cli.py fails when the document and the schema disagree.)"""
import re
from pathlib import Path

from mtwin.twin.machine import machine_toml

doc = Path(__file__).with_name("configuration.md")
text = doc.read_text()
block = "## The default machine (`mtwin config show`)\n\n```toml\n" + machine_toml().rstrip() + "\n```\n"
text = re.sub(r"## The default machine \(`mtwin config show`\)\n\n```toml\n.*?```\n", lambda m: block, text,
              flags=re.S)
doc.write_text(text)
