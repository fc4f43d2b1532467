"""Build hook: a wheel carries the top-level scenes/ folder inside the package, as implc/scene_files/.

Everything else about the build is declared in pyproject.toml. A source checkout (and an editable
install) reads scenes/ where it is; see implc.files.scene.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithScenes(build_py):
    def run(self):
        super().run()
        target = Path(self.build_lib) / "implc" / "scene_files"
        target.mkdir(parents=True, exist_ok=True)
        for scene in sorted(Path(__file__).resolve().parent.joinpath("scenes").glob("*.py")):
            shutil.copy2(scene, target / scene.name)


setup(cmdclass={"build_py": BuildWithScenes})
