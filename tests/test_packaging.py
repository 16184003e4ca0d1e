"""What a user installs and cites: the version, the licence and the citation agree across
pyproject.toml, the package, LICENSE, CITATION.cff and the README."""

import importlib.metadata
import re
import tomllib
from pathlib import Path

import jmse_jax

ROOT = Path(__file__).resolve().parents[1]


def _project():
    return tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]


def _cff_values(key):
    """Every value of ``key`` in CITATION.cff at any indentation, inline or folded (``>-``).

    A small reader for the subset of YAML the file uses (no YAML library is a dependency)."""
    lines = (ROOT / "CITATION.cff").read_text().splitlines()
    values = []
    for i, line in enumerate(lines):
        match = re.fullmatch(r"(\s*)(?:- )?" + re.escape(key) + r":\s*(.*)", line)
        if not match:
            continue
        indent, value = len(match.group(1)), match.group(2).strip()
        if value == ">-":
            folded = []
            for following in lines[i + 1:]:
                if following.strip() and len(following) - len(following.lstrip()) <= indent:
                    break
                folded.append(following.strip())
            value = " ".join(part for part in folded if part)
        values.append(value.strip('"'))
    return values


def test_the_version_is_the_same_everywhere():
    version = _project()["version"]
    assert jmse_jax.__version__ == version
    assert _cff_values("version") == [version]
    assert importlib.metadata.version("jmse_jax") == version


def test_the_licence_is_declared_and_shipped():
    project = _project()
    assert project["license"] == "MIT"
    assert _cff_values("license") == ["MIT"]
    assert project["license-files"] == ["LICENSE"]
    text = (ROOT / "LICENSE").read_text()
    assert text.splitlines()[0] == "MIT License"
    assert "Permission is hereby granted, free of charge" in text


def test_the_citation_file_names_the_package_and_the_papers_the_readme_cites():
    assert _cff_values("cff-version") == ["1.2.0"]
    titles = _cff_values("title")
    assert titles[0].startswith("jmse_jax:")
    reference = (ROOT / "README.md").read_text().split("## Reference", 1)[1]
    reference = " ".join(reference.split())
    cited = titles[1:]
    assert len(cited) == 2
    for title in cited:
        assert title in reference, title
    assert _cff_values("family-names") == ["Stork", "Robinson", "Berkner", "Shroff"]
