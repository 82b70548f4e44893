"""Issue 42 item 15: what the README's examples write in the checkout (the files of its commands'
-o and --png, the data set's views/ folder, the Python examples' files) is ignored by git, so that
a reader who tries them keeps a clean `git status`."""
import re
import subprocess

from conftest import REPO

README = (REPO / "README.md").read_text()


def outputs() -> set[str]:
    names = set()
    for block in re.findall(r"```(?:sh|python)\n(.*?)```", README, flags=re.S):
        for match in re.finditer(r"(?:-o|--output)\s+(\S+)", block):
            out = match.group(1)
            names.add(out)
            if "--png" in block.splitlines()[block[:match.start()].count("\n")]:
                stem = out.rsplit(".", 1)[0]
                names.update(f"{stem}.{aov}.png" for aov in ("depth", "normal", "id", "label"))
        names.update(re.findall(r"write_(?:exr|npz)\(f?\"([^\"{]+)", block))
        names.update(f"{folder}/view00.npz" for folder in re.findall(r"Path\(\"([^\"]+)\"\)\.mkdir", block))
    names.update(re.findall(r"`pyclray [^`]*?-o ([\w./-]+)[^`]*`", README))  # the commands in the prose
    names.discard("out.tiff")  # the example of a refused -o: nothing is written
    return {name for name in names if re.search(r"\.\w+$", name)}  # (an f-string's stem cut at its "{" left out)


def test_the_readme_examples_outputs_are_ignored_by_git():
    names = outputs()
    for expected in ("tp02.exr", "shapes.npz", "orbit.gif", "lit.png", "views/view00.npz", "m.png", "scene.xml"):
        assert expected in names, (expected, names)
    check = subprocess.run(["git", "check-ignore", "--no-index", "-v", *sorted(names)], cwd=REPO,
                           capture_output=True, text=True)
    ignored = {line.split("\t", 1)[1] for line in check.stdout.splitlines()}
    assert ignored == names, sorted(names - ignored)
