"""The names of the face's regions (vertex index sets), and which of them each consumer needs.

A face (facegen.face.mesh.Mesh) carries its regions in `mesh.regions`, a dict name -> 0-based vertex indices.
The procedural face (facegen.face.procedural) has all of FACE_REGIONS; a dataset in the community layout
has at least the two evaluation regions, stored as the community's files regions/lve.txt (the lips, where
LVE is measured) and regions/fdd.txt (the upper face, where FDD is measured). Every other region file is
named after its region.
"""

from __future__ import annotations

import numpy as np

LIPS = "lips"  # the lips and the skin just around them (LVE)
UPPER_FACE = "upper_face"  # forehead, brows and lids: what the mouth must not move (FDD)

# the community's region file stems -> region names (every other region file is named after its region)
COMMUNITY_FILES: dict[str, str] = {"lve": LIPS, "fdd": UPPER_FACE}

# what the motion rig (facegen.face.rig) deforms the face by
RIG_REGIONS = ("jaw", "jaw_hinge", "mouth_upper_margin", "mouth_lower_margin", "left_eyeball",
               "right_eyeball", "left_upper_lid_margin", "left_lower_lid_margin", "right_upper_lid_margin",
               "right_lower_lid_margin", "brows", "forehead", "cheeks")
# what ARKit's 52 shapes (facegen.arkit.shapes) are built on: the rig's and the nose (noseSneer)
ARKIT_REGIONS = RIG_REGIONS + ("nose",)
# what the lip-sync metrics (facegen.lipsync) measure on
LIPSYNC_REGIONS = ("mouth_upper_margin", "mouth_lower_margin", "left_eyeball", "right_eyeball", LIPS,
                   UPPER_FACE)
# every region of the procedural face (facegen.face.procedural)
FACE_REGIONS = tuple(sorted({*RIG_REGIONS, "nose", LIPS, UPPER_FACE, "upper_lids", "lower_lids",
                             "mouth_cavity"}))


def mouth_middle(regions: dict) -> tuple[np.ndarray, np.ndarray]:
    """(upper, lower) int64 vertex indices: the facing margin vertices of the middle third of the mouth (the
    k-th upper faces the k-th lower), where lip aperture is measured (facegen.lipsync) and shut
    (facegen.lip_seal)."""
    from facegen.errors import FacegenError

    mu = np.asarray(regions["mouth_upper_margin"], np.int64)
    ml = np.asarray(regions["mouth_lower_margin"], np.int64)
    if len(mu) != len(ml) or len(mu) < 3:
        raise FacegenError(f"the mouth margins must pair up (at least 3 each), got {len(mu)} upper and "
                           f"{len(ml)} lower vertices")
    third = len(mu) // 3
    return mu[third:len(mu) - third], ml[third:len(ml) - third]


def region_name(stem: str) -> str:
    """The region a region file called `stem`.txt holds: lve -> lips, fdd -> upper_face, others by name."""
    return COMMUNITY_FILES.get(stem, stem)


def file_stem(name: str) -> str:
    """The file stem region `name` is stored under (the inverse of `region_name`): lips -> lve,
    upper_face -> fdd, others by name."""
    return _STEMS.get(name, name)


_STEMS = {name: stem for stem, name in COMMUNITY_FILES.items()}
