"""Build hook: the wheel carries a copy of ``configs/`` as ``teleop/configs/`` (package data).

Everything else about the build is in pyproject.toml. ``configs/`` stays the top-level folder users edit;
the copy lets an installed (non-editable) package find its defaults (teleop/config/files.py).
"""
from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


class BuildPyWithConfigs(build_py):
    """build_py, then ``configs/**/*.yaml`` copied under ``teleop/configs/`` of the build."""

    def run(self) -> None:
        super().run()
        target = Path(self.build_lib) / "teleop" / "configs"
        for src in sorted((ROOT / "configs").rglob("*.yaml")):
            dst = target / src.relative_to(ROOT / "configs")
            dst.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(src, dst)


setup(cmdclass={"build_py": BuildPyWithConfigs})
