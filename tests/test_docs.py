"""The design notes the code cites live in the repository, and the README's Python example runs."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_every_cited_design_section_exists():
    design = (ROOT / "docs" / "DESIGN.md").read_text()
    headings = [h.lower() for h in re.findall(r"^## (.+)$", design, flags=re.M)]
    cited = set()
    for path in [*ROOT.glob("pipeline/**/*.py"), *ROOT.glob("viz/*.py")]:
        text = path.read_text()
        assert "DESIGN.md" not in text.replace("docs/DESIGN.md", ""), path
        cited |= set(re.findall(r'docs/DESIGN\.md,? "([^"]+)"', text))
    assert cited
    for section in cited:
        assert any(section.lower().split(" —")[0] in h for h in headings), section


def test_readme_python_example_runs():
    readme = (ROOT / "README.md").read_text()
    blocks = re.findall(r"```python\n(.*?)```", readme, flags=re.S)
    example = next(b for b in blocks if "resolve_conflicts" in b)
    namespace: dict = {}
    exec(compile(example, "README.md", "exec"), namespace)  # noqa: S102 - our own example
    assert namespace["result"].deleted.sum() == 1


def test_readme_run_images_line_names_every_option():
    from pipeline.__main__ import build_parser

    readme = (ROOT / "README.md").read_text()
    block = re.search(r"^formation-match run-images .*?(?=^formation-match )", readme,
                      flags=re.M | re.S).group(0)
    sub = build_parser(["run-images"])._subparsers._group_actions[0].choices["run-images"]
    options = {o for a in sub._actions for o in a.option_strings if o.startswith("--")}
    missing = sorted(o for o in options - {"--help", "--quiet", "--version", "--transport"}
                     if not re.search(re.escape(o) + r"(?![\w-])", block))
    assert not missing
    assert "`run-formation`, `run-formations`, `run-images` and `resolve` take `--transport" \
        in readme


def test_readme_says_where_make_setup_puts_the_command():
    # the README showed the bare `formation-match` after `make setup`, which installs it in
    # .venv/bin only: typed as shown, a new user's shell said 'command not found'
    import tomllib

    readme = (ROOT / "README.md").read_text()
    commands = readme.split("## Commands", 1)[1].split("```", 1)[0]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert "formation-match" in project["scripts"]
    assert "`.venv/bin/formation-match`" in commands
    assert "source .venv/bin/activate" in commands
    assert "VENV   := .venv" in (ROOT / "Makefile").read_text()


def test_architecture_names_every_rule_and_both_defaults():
    # the registry row named two of the four rules and only DEFAULT_RESOLUTION, saying that
    # clean-h5 and run-landmarks "name theirs": resolve and clean-db run sync by default too
    from pipeline.consistency import rules

    row = next(line for line in (ROOT / "docs" / "architecture.md").read_text().splitlines()
               if line.startswith("| resolution rule"))
    assert all(f"`{name}`" in row for name in ("paper", "evidence", "sync", "paper-labels"))
    for constant in ("DEFAULT_RESOLUTION", "DEFAULT_LINKS_RESOLUTION"):
        assert f"`{constant}` (`{getattr(rules, constant)}`)" in row
    for command in ("resolve", "clean-db", "clean-h5", "run-landmarks"):
        assert f"`{command}`" in row
