"""The G codes' modal groups as RS274NGC 3 (NIST IR 6556, table 4) and LinuxCNC's G-code
reference list them, by the codes as a programmer writes them — and the one rule: a block may
hold at most one code of a modal group.

The exceptions mtwin makes on purpose, each named here:

* ``G80`` beside a motion code (``G0 G80``): Fanuc posts write it; Fanuc puts G80 in group 09,
  apart from the motion group, so neither dialect refuses it;
* Fanuc's own codes (G05/G05.1/G08 look-ahead switches, G09, G15/G16, G50.1/G51.1, G68/G69) in
  their Fanuc groups; G50/G67 (scaling and macro-call cancels) belong to no group the twin reads.
"""
from __future__ import annotations

#: RS274NGC / LinuxCNC: modal group -> codes
LINUXCNC = {
    0: ["G4", "G10", "G28", "G28.1", "G30", "G30.1", "G52", "G53", "G92", "G92.1", "G92.2", "G92.3"],
    1: ["G0", "G1", "G2", "G3", "G33", "G33.1", "G38.2", "G38.3", "G38.4", "G38.5", "G73", "G76", "G81", "G82",
        "G83", "G84", "G85", "G86", "G89", "G5", "G5.1"],
    2: ["G17", "G18", "G19"],
    3: ["G90", "G91"],
    4: ["G90.1", "G91.1"],
    5: ["G93", "G94", "G95"],
    6: ["G20", "G21"],
    7: ["G40", "G41", "G42", "G41.1", "G42.1"],
    8: ["G43", "G43.1", "G43.2", "G49"],
    10: ["G98", "G99"],
    12: ["G54", "G55", "G56", "G57", "G58", "G59", "G59.1", "G59.2", "G59.3"],
    13: ["G61", "G61.1", "G64"],
    14: ["G96", "G97"],
    15: ["G7", "G8"],
}
#: Fanuc (0i/30i milling): the groups of the codes that differ from LinuxCNC's reading
FANUC_OWN = {
    16: ["G68", "G69"],
    17: ["G15", "G16"],
    22: ["G50.1", "G51.1"],
}
#: codes of no conflict group: G80 (see above), Fanuc's G09 and look-ahead switches, cancels
FREE = {"linuxcnc": ["G80", "G50", "G67", "G69", "G50.1", "G15"],
        "fanuc": ["G80", "G9", "G5", "G5.1", "G8", "G50", "G67"]}


def group_of(code: str, dialect: str) -> int | None:
    """The modal group of a code in a dialect (None: no group — it conflicts with nothing)."""
    if code in FREE[dialect]:
        return None
    table = dict(LINUXCNC)
    if dialect == "fanuc":
        own = {c for codes in FANUC_OWN.values() for c in codes}
        table = {g: [c for c in codes if c not in own and c not in ("G5", "G5.1", "G7", "G8")]
                 for g, codes in table.items()}
        table.update(FANUC_OWN)
    for g, codes in table.items():
        if code in codes:
            return g
    raise KeyError(f"{code} is not in the reference for {dialect}")


def conflicts(codes: list[str], dialect: str) -> bool:
    """Do these G codes, in one block, break the one-code-per-group rule?"""
    groups = [group_of(c, dialect) for c in codes]
    groups = [g for g in groups if g is not None]
    return len(groups) != len(set(groups))


#: LinuxCNC's M-code modal groups (interp_array.cc, ``ems[]``): group -> the codes the twin reads
#: (a block may hold one code of each; Fanuc checks no M groups: a block may carry up to three)
LINUXCNC_M = {
    4: ["M0", "M1", "M2", "M30", "M99"],
    5: ["M62", "M63", "M64", "M65", "M66", "M67", "M68"],
    6: ["M6", "M61"],
    7: ["M3", "M4", "M5", "M19", "M70", "M71", "M72", "M73"],
    8: ["M7", "M8", "M9"],
    9: ["M48", "M49", "M50", "M51", "M52", "M53"],
}


def m_conflicts(codes: list[str], dialect: str) -> bool:
    """Do these M codes, in one block, break the one-code-per-group rule?"""
    if dialect == "fanuc":
        return False
    groups = [g for c in codes for g, cs in LINUXCNC_M.items() if c in cs]
    return len(groups) != len(set(groups))
