"""The thirteen object classes of the paper (Table 1) with realistic sizes and IFC typing.

Sizes are the footprint seen straight on (``width_m`` along the wall, ``height_m`` up)
and how far the object stands out of the wall (``depth_m``). ``mount_height_m`` is a
typical height of the footprint centre above the floor, used to lay out scenarios.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ObjectSpec:
    class_id: str
    name: str
    width_m: float
    height_m: float
    depth_m: float
    ifc_class: str
    predefined_type: str
    mount_height_m: float
    object_type: str | None = None  # IFC ObjectType where the predefined type is USERDEFINED
    mount: tuple[str, ...] = ("wall", "column")  # surfaces it may be on (model.json "mount")


CLASS_ORDER: tuple[str, ...] = (
    "electrical_panel", "socket_x1", "socket_x2", "socket_x4", "builtin_socket", "switch",
    "fire_extinguisher", "radiator", "fire_alarm_switch", "smoke_detector", "exit_light",
    "extinguisher_sign", "fire_alarm_switch_sign",
)

CATALOGUE: dict[str, ObjectSpec] = {s.class_id: s for s in (
    ObjectSpec("electrical_panel", "Electrical panel", 0.40, 0.50, 0.10,
               "IfcElectricDistributionBoard", "DISTRIBUTIONBOARD", 1.60, mount=("wall",)),
    ObjectSpec("socket_x1", "Socket x1", 0.08, 0.08, 0.012, "IfcOutlet", "POWEROUTLET", 0.30),
    ObjectSpec("socket_x2", "Socket x2", 0.15, 0.08, 0.012, "IfcOutlet", "POWEROUTLET", 0.30),
    ObjectSpec("socket_x4", "Socket x4", 0.29, 0.08, 0.012, "IfcOutlet", "POWEROUTLET", 0.30),
    ObjectSpec("builtin_socket", "Built-in socket", 0.12, 0.12, 0.004, "IfcOutlet", "POWEROUTLET", 0.30,
               mount=("wall",)),
    ObjectSpec("switch", "Switch", 0.08, 0.08, 0.012, "IfcSwitchingDevice", "TOGGLESWITCH", 1.10),
    ObjectSpec("fire_extinguisher", "Fire extinguisher", 0.20, 0.60, 0.18,
               "IfcFireSuppressionTerminal", "USERDEFINED", 1.20, object_type="FIREEXTINGUISHER"),
    ObjectSpec("radiator", "Radiator", 0.80, 0.60, 0.10, "IfcSpaceHeater", "RADIATOR", 0.45, mount=("wall",)),
    ObjectSpec("fire_alarm_switch", "Fire alarm switch", 0.10, 0.10, 0.05, "IfcAlarm",
               "MANUALPULLBOX", 1.40),
    ObjectSpec("smoke_detector", "Smoke detector", 0.11, 0.11, 0.05, "IfcSensor", "SMOKESENSOR", 2.30,
               mount=("wall", "ceiling")),
    ObjectSpec("exit_light", "Exit light", 0.36, 0.14, 0.05, "IfcLightFixture", "SECURITYLIGHTING", 2.25,
               mount=("wall", "ceiling")),
    ObjectSpec("extinguisher_sign", "Extinguisher sign", 0.21, 0.30, 0.003, "IfcSign", "PICTORAL",
               1.95, object_type="EXTINGUISHERSIGN"),
    ObjectSpec("fire_alarm_switch_sign", "Fire alarm switch sign", 0.21, 0.21, 0.003, "IfcSign",
               "PICTORAL", 1.75, object_type="FIREALARMSWITCHSIGN"),
)}

# Table 1 of the paper: instances per class in Scenario I (116 in all).
TABLE1_COUNTS: dict[str, int] = dict(zip(CLASS_ORDER, (4, 20, 6, 11, 6, 16, 9, 6, 8, 10, 3, 9, 8), strict=True))
