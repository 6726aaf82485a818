"""Show the spm-opt robot in 3D Slicer 5 (with the SlicerOpenIGTLink extension): run in
Slicer's Python console, e.g. exec(open("/path/to/spm_opt/docs/guide/slicer_setup.py").read()).
The guide is docs/guide/slicer.md.

Written against SlicerOpenIGTLink's API as read in openigtlink/SlicerOpenIGTLink at commit
d090ca4fa6400913b9cdf7efbc89f1f0afa4f770 (OpenIGTLinkIF/MRML/vtkMRMLIGTLConnectorNode.h
and .cxx) and Slicer's own at tag v5.0.0 (vtkMRMLScene, vtkMRMLMarkupsNode,
Base/Python/slicer/util.py); not run in Slicer by us.
"""

import itertools
import time

import slicer
import vtk

REPOSITORY = "/path/to/spm_opt"  # this repository's folder on the Slicer machine
SKULL_MESHES = [  # in RAS: their header says SPACE=RAS, which Slicer's STL reader follows
    REPOSITORY + "/problems/skull/skull_outer.stl",
    REPOSITORY + "/problems/skull/skull_inner.stl",
]
HOST, PORT = "localhost", 18944  # where spm-opt navigate / execute --igtl listens
TOOL_LENGTH_MM, TOOL_RADIUS_MM = 40.0, 1.5


def node(class_name, name):
    """The scene's node of that class and name, made if missing. A message updates the
    node named as its device (the connector looks it up by exact name, GetFirstNode)."""
    found = slicer.mrmlScene.GetFirstNode(name, class_name)
    return found or slicer.mrmlScene.AddNewNodeByClass(class_name, name)


# The client: it tries to connect every 0.1 s until a server listens, and again after the
# server goes (spm-opt navigate, then spm-opt execute), for as long as it is active.
connector = node("vtkMRMLIGTLConnectorNode", "spm-opt")
connector.SetTypeClient(HOST, PORT)
connector.Start()

# The skull, in RAS like the image: no transform. Only a model drawn in the robot's frame
# (its CAD, say) would go under RobotToRAS; every model the link sends is in RAS already.
for path in SKULL_MESHES:
    slicer.util.loadModel(path)

# The tool: a cylinder on its own z axis from the tip (z = 0) outward (z = +40 mm), the side
# it comes from, moved by the ToolToRAS the link streams.
cylinder = vtk.vtkCylinderSource()  # along y, centred on the origin
cylinder.SetHeight(TOOL_LENGTH_MM)
cylinder.SetRadius(TOOL_RADIUS_MM)
cylinder.SetResolution(24)
onto_z = vtk.vtkTransform()  # applied right to left: y turned onto z, then moved up
onto_z.Translate(0.0, 0.0, TOOL_LENGTH_MM / 2)
onto_z.RotateX(90.0)
shaft = vtk.vtkTransformPolyDataFilter()
shaft.SetInputConnection(cylinder.GetOutputPort())
shaft.SetTransform(onto_z)
shaft.Update()
tool = node("vtkMRMLModelNode", "Tool")
tool.SetAndObservePolyData(shaft.GetOutput())
tool.CreateDefaultDisplayNodes()
tool.SetAndObserveTransformNodeID(node("vtkMRMLLinearTransformNode", "ToolToRAS").GetID())

# What Slicer sends when it changes (a point list: a point added or moved, not deleted):
# the flap, a point list (the only markups type SlicerOpenIGTLink sends, as POINT), and the
# registration RASToRobot (RAS mm -> robot mm), e.g. SlicerIGT's Fiducial Registration Wizard's.
flap = node("vtkMRMLMarkupsFiducialNode", "Flap")
flap.CreateDefaultDisplayNodes()
registration = node("vtkMRMLLinearTransformNode", "RASToRobot")
for outgoing in (flap, registration):
    connector.RegisterOutgoingMRMLNode(outgoing)

# Command ids are <the script's start, s since 1970>-<count>, so a later session reuses no
# id of an earlier one: PLAN names its files after the id (flap_<id>.toml, ...).
_session, _count = int(time.time()), itertools.count(1)


def send_command(text):
    """Send STRING CMD_<id> with ``text``; the answers arrive as the text node ACK_<id>
    (the command echoed) and the status node CMD_<id> (see answer()). Returns the id."""
    command_id = f"{_session}-{next(_count)}"
    command = slicer.mrmlScene.AddNewNodeByClass("vtkMRMLTextNode", "CMD_" + command_id)
    command.SetText(text)  # before registering: a registered text node is sent on each change
    connector.RegisterOutgoingMRMLNode(command)
    connector.PushNode(command)
    return command_id


def stop():  # the safe stop, as Ctrl-C at the robot's console
    return send_command("STOP")


def hold():  # the feed hold, as the space key
    return send_command("HOLD")


def resume():  # the end of a hold, as the space key again
    return send_command("RESUME")


def plan(planner="toppra"):  # spm-opt navigate: plan the flap last sent; see CMD_<id>
    return send_command("PLAN " + planner)


def send_flap():  # Flap now (by itself, it is sent only when it changes)
    connector.PushNode(flap)


def flap_from(curve):
    """Copy a markups curve's points (e.g. slicer.util.loadMarkups of
    problems/skull/flap.mrk.json, a closed curve, which is not sent) into Flap, and send it."""
    flap.RemoveAllControlPoints()
    for i in range(curve.GetNumberOfControlPoints()):
        flap.AddControlPointWorld(
            curve.GetNthControlPointPositionWorld(i), curve.GetNthControlPointLabel(i)
        )
    send_flap()


def answer(name):
    """A received STATUS (RunState, CMD_<id>) as (code, name, message), or a
    received STRING's text (RunInfo, ACK_<id>); None before it arrives."""
    status = slicer.mrmlScene.GetFirstNode(name, "vtkMRMLIGTLStatusNode")
    if status:
        return status.GetCode(), status.GetErrorName(), status.GetStatusString()
    text = slicer.mrmlScene.GetFirstNode(name, "vtkMRMLTextNode")
    return text.GetText() if text else None
