"""deploy/Dockerfile as both checks read it: its stages, and what the last (runtime) stage sets."""

import re
from pathlib import Path

from dockerfile_parse import DockerfileParser

DOCKERFILE = Path(__file__).resolve().parents[1] / "Dockerfile"


class Dockerfile:
    def __init__(self, path=DOCKERFILE):
        self.text = path.read_text()
        self.parser = DockerfileParser(path=str(path))
        # Global ARGs before the first FROM belong to no stage.
        self.stages = []
        for instruction in self.parser.structure:
            if instruction["instruction"] == "FROM":
                self.stages.append([])
            if self.stages:
                self.stages[-1].append(instruction)
        self.runtime = self.stages[-1] if self.stages else []

    def values(self, kind):
        """Every value of one instruction kind in the runtime stage, in order."""
        return [i["value"] for i in self.runtime if i["instruction"] == kind]

    def last(self, kind):
        values = self.values(kind)
        return values[-1] if values else None

    def packages(self):
        """The packages the runtime stage's first `apt-get install` names (options left out)."""
        for command in self.values("RUN"):
            match = re.search(r"apt-get install ([^&;]*)", command)
            if match:
                return [w for w in match.group(1).split() if not w.startswith("-")]
        return []

    def env(self):
        """ENV of the runtime stage, with `KEY=VALUE \\` continuations resolved."""
        return dict(self.parser.envs)

    def global_arg(self, name):
        match = re.search(rf"^ARG {name}=(\S+)$", self.text, re.M)
        return match.group(1) if match else None
