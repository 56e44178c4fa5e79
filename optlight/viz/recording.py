"""The preview's scene as recorded meshcat commands: :class:`SceneRecorder` stands in for meshcat's
viewer window and keeps the scene tree its server keeps, so that the scene can be replayed into a
standalone HTML page (:data:`HTML_TEMPLATE`) or sent to a live server."""

from __future__ import annotations

from typing import Any

import umsgpack
from meshcat.servers.tree import SceneTree, find_node


class SceneCommand:
    """A meshcat command given as its message (``lower()`` returns it), for what meshcat-python's
    command classes cannot say: an animation whose tracks are typed arrays."""

    def __init__(self, message: dict[str, Any]) -> None:
        self.message = message

    def lower(self) -> dict[str, Any]:
        """The message, as meshcat's command classes give theirs."""
        return self.message


class SceneRecorder:
    """Stands in for meshcat's ``ViewerWindow``: keeps the commands sent to it in the scene tree
    meshcat's server keeps (last transform wins, ``set_object`` clears a node's properties), and
    gives them back in an order a viewer can replay (the animation last, after its targets)."""

    def __init__(self) -> None:
        self.tree = SceneTree()
        self.animation: bytes | None = None

    def send(self, command: Any) -> None:
        """Record one meshcat command (``SetObject``, ``SetTransform``, ``SetProperty``,
        ``SetAnimation`` or pinocchio's ``DaeMeshGeometry``)."""
        data = command.lower()
        packed = umsgpack.packb(data)
        kind = data["type"]
        node = find_node(self.tree, [p for p in data["path"].split("/") if p])
        if kind == "set_object":
            node.object = packed
            node.properties = []
        elif kind == "set_transform":
            node.transform = packed
        elif kind == "set_property":
            node.properties.append(packed)
        elif kind == "set_animation":
            self.animation = packed
        else:
            raise ValueError(f"the preview does not record meshcat {kind!r} commands")

    def commands(self) -> list[tuple[str, str, bytes]]:
        """(type, path, packed command) for every recorded command, parents before children."""
        out: list[tuple[str, str, bytes]] = []
        stack: list[tuple[str, Any]] = [("", self.tree)]
        while stack:
            path, node = stack.pop()
            if node.object is not None:
                out.append(("set_object", path, node.object))
            out.extend(("set_property", path, p) for p in node.properties)
            if node.transform is not None:
                out.append(("set_transform", path, node.transform))
            stack.extend((f"{path}/{name}", child) for name, child in reversed(list(node.items())))
        if self.animation is not None:
            out.append(("set_animation", "", self.animation))
        return out


#: The standalone page of a recorded scene: meshcat's viewer replays the inlined commands.
HTML_TEMPLATE = """<!DOCTYPE html>
<html>
<head>
<meta charset="utf-8">
<title>{title}</title>
<style>body {{ margin: 0; }} #meshcat-pane {{ width: 100vw; height: 100vh; overflow: hidden; }}</style>
</head>
<body>
<div id="meshcat-pane"></div>
<script>{viewer_js}</script>
<script type="application/json" id="optlight-scene">{commands}</script>
<script>
var viewer = new MeshCat.Viewer(document.getElementById("meshcat-pane"));
for (const command of JSON.parse(document.getElementById("optlight-scene").textContent)) {{
  const bytes = atob(command);
  const buffer = new Uint8Array(bytes.length);
  for (let i = 0; i < bytes.length; i++) buffer[i] = bytes.charCodeAt(i);
  viewer.handle_command_bytearray(buffer);
}}
</script>
</body>
</html>
"""
