"""Build hooks; the project's metadata is in pyproject.toml.

The package page's README is README.md with its relative links made absolute (to the repository on
GitHub: pages to ``blob/main/<path>``, images to their raw file), since a package index shows the text
without the repository's files.

The repository's top-level ``hands/<name>/`` and ``checkpoints/`` folders go into the wheel as package
data, ``opend_mj/_data/hands/<name>/`` and ``opend_mj/_data/checkpoints/``, where
`opend_mj.resources` finds them. An editable install gets no copy: `opend_mj.resources` reads the
top-level folders of the clone itself, so there is one source of truth.
"""

import re
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent
REPOSITORY = "https://github.com/opend-mj/opend-mj"
RAW = "https://raw.githubusercontent.com/opend-mj/opend-mj/main"
#: a Markdown link or image with a relative target (no scheme, not an anchor of the page itself)
RELATIVE_LINK = re.compile(r"(!?)\[([^\]]*)\]\((?![a-z][a-z0-9+.-]*:|#)([^)\s]+)\)")
#: folder -> the glob patterns of its files that ship (hands: each hand's folder, not the generator
#: script beside them; checkpoints: the weights with their cards and training curves).
SHIPPED = {"hands": ("*/*",), "checkpoints": ("*",)}


class BuildPyWithData(build_py):
    """``build_py`` that also copies the shipped hands and checkpoints into ``opend_mj/_data``."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return
        target = Path(self.build_lib) / "opend_mj" / "_data"
        for folder, patterns in SHIPPED.items():
            files = sorted({f for pattern in patterns for f in (ROOT / folder).glob(pattern) if f.is_file()})
            if not files:
                raise FileNotFoundError(f"{ROOT / folder}: nothing to ship (a source tree without {folder}/?)")
            for src in files:
                dest = target / folder / src.relative_to(ROOT / folder)
                self.mkpath(str(dest.parent))
                self.copy_file(str(src), str(dest))


def package_page_readme(text: str) -> str:
    """``text`` (README.md) with every relative link and image made absolute to the repository."""
    def absolute(match: re.Match) -> str:
        bang, label, target = match.groups()
        return f"{bang}[{label}]({RAW if bang else REPOSITORY + '/blob/main'}/{target})"

    return RELATIVE_LINK.sub(absolute, text)


setup(cmdclass={"build_py": BuildPyWithData},
      long_description=package_page_readme((ROOT / "README.md").read_text(encoding="utf-8")),
      long_description_content_type="text/markdown")
