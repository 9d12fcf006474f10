"""Joint hierarchies of mocap systems' BVH exports, rebuilt from real files (names, parents,
OFFSETs and channel orders exactly as exported; fingers cut down where a test does not need them),
and a writer that turns one into BVH text with T-pose or given frames.  Nothing here is read from
disk: tests write the text into ``tmp_path``.

Sources (public repositories): Perception Neuron / Axis Neuron BVH
header (a UDP-to-BVH bridge that prepends Axis Neuron's header; body joints, the thumb and index
roots), Rokoko Studio BVH (facebookresearch/AnimatedDrawings
``examples/bvh/rokoko/jesse_dance.bvh``: the whole header and four of its frames; that repository
is under the MIT licence, Copyright (c) Meta Platforms, Inc. and affiliates), Xsens MVN BVH (a
BVH toolkit's ``xsens_hierarchy()``).
"""
from __future__ import annotations

from typing import Optional, Sequence

#: (name, parent, OFFSET, channel set index, End Site OFFSET or None), in file order
NEURON_CHANNELS = ('Xposition Yposition Zposition Yrotation Xrotation Zrotation',)
NEURON = (
    ('Hips', None, (0.0, 105.85, 0.0), 0, None),
    ('RightUpLeg', 'Hips', (-11.5, -1.85, 0.0), 0, None),
    ('RightLeg', 'RightUpLeg', (0.0, -48.0, 0.0), 0, None),
    ('RightFoot', 'RightLeg', (0.0, -48.0, 0.0), 0, (0.0, -8.0, 19.6)),
    ('LeftUpLeg', 'Hips', (11.5, -1.85, 0.0), 0, None),
    ('LeftLeg', 'LeftUpLeg', (0.0, -48.0, 0.0), 0, None),
    ('LeftFoot', 'LeftLeg', (0.0, -48.0, 0.0), 0, (0.0, -8.0, 19.6)),
    ('Spine', 'Hips', (0.0, 16.654, 0.0), 0, None),
    ('Spine1', 'Spine', (0.0, 11.312, 0.0), 0, None),
    ('Spine2', 'Spine1', (0.0, 11.78, 0.0), 0, None),
    ('Spine3', 'Spine2', (0.0, 11.312, 0.0), 0, None),
    ('Neck', 'Spine3', (0.0, 12.091, 0.0), 0, None),
    ('Head', 'Neck', (0.0, 9.0, 0.0), 0, (0.0, 18.0, 0.0)),
    ('RightShoulder', 'Spine3', (-3.5, 8.061, 0.0), 0, None),
    ('RightArm', 'RightShoulder', (-14.0, 0.0, 0.0), 0, None),
    ('RightForeArm', 'RightArm', (-29.0, 0.0, 0.0), 0, None),
    ('RightHand', 'RightForeArm', (-28.0, 0.0, 0.0), 0, None),
    ('RightHandThumb1', 'RightHand', (-2.702, 0.206, 3.388), 0, (-3.998, 0.0, 0.0)),
    ('RightInHandIndex', 'RightHand', (-3.5, 0.552, 2.148), 0, None),
    ('RightHandIndex1', 'RightInHandIndex', (-5.664, -0.099, 1.085), 0, (-3.93, 0.0, 0.0)),
    ('LeftShoulder', 'Spine3', (3.5, 8.061, 0.0), 0, None),
    ('LeftArm', 'LeftShoulder', (14.0, 0.0, 0.0), 0, None),
    ('LeftForeArm', 'LeftArm', (29.0, 0.0, 0.0), 0, None),
    ('LeftHand', 'LeftForeArm', (28.0, 0.0, 0.0), 0, None),
    ('LeftHandThumb1', 'LeftHand', (2.702, 0.206, 3.388), 0, (3.998, 0.0, 0.0)),
    ('LeftInHandIndex', 'LeftHand', (3.5, 0.552, 2.148), 0, None),
    ('LeftHandIndex1', 'LeftInHandIndex', (5.664, -0.099, 1.085), 0, (3.93, 0.0, 0.0)),
)

#: (name, parent, OFFSET, channel set index, End Site OFFSET or None), in file order
ROKOKO_CHANNELS = ('Xposition Yposition Zposition Yrotation Xrotation Zrotation', 'Yrotation Xrotation Zrotation')
ROKOKO = (
    ('Hips', None, (0.0, 94.0, 0.0), 0, None),
    ('Spine', 'Hips', (0.0, 12.9947, 0.0), 1, None),
    ('Spine1', 'Spine', (12.7099, 0.0, 0.0), 1, None),
    ('Spine2', 'Spine1', (12.7829, 0.0, 0.0), 1, None),
    ('LeftShoulder', 'Spine2', (10.4351, -7.0401, 1.9147), 1, None),
    ('LeftArm', 'LeftShoulder', (13.4599, 0.0, 0.0), 1, None),
    ('LeftForeArm', 'LeftArm', (26.1001, 0.0, 0.0001), 1, None),
    ('LeftHand', 'LeftForeArm', (28.9001, 0.0, 0.0), 1, None),
    ('LeftInHandIndex', 'LeftHand', (2.6469, -0.103, 1.6042), 1, None),
    ('LeftHandIndex1', 'LeftInHandIndex', (5.427, 0.0, 0.9569), 1, None),
    ('LeftHandIndex2', 'LeftHandIndex1', (4.5806, 0.0, 0.0), 1, None),
    ('LeftHandIndex3', 'LeftHandIndex2', (2.8181, -0.0001, 0.0), 1, (1.409, 0.0, 0.0)),
    ('LeftInHandMiddle', 'LeftHand', (2.7689, -0.103, 0.545), 1, None),
    ('LeftHandMiddle1', 'LeftInHandMiddle', (5.3677, 0.0, 0.0), 1, None),
    ('LeftHandMiddle2', 'LeftHandMiddle1', (4.7024, 0.0, 0.0), 1, None),
    ('LeftHandMiddle3', 'LeftHandMiddle2', (3.1016, 0.0, 0.0), 1, (1.5508, 0.0, 0.0)),
    ('LeftInHandPinky', 'LeftHand', (2.4891, -0.103, -1.4884), 1, None),
    ('LeftHandPinky1', 'LeftInHandPinky', (4.529, 0.0, -1.6484), 1, None),
    ('LeftHandPinky2', 'LeftHandPinky1', (3.5541, 0.0, 0.0), 1, None),
    ('LeftHandPinky3', 'LeftHandPinky2', (2.234, 0.0, 0.0), 1, (1.117, 0.0, 0.0)),
    ('LeftInHandRing', 'LeftHand', (2.7444, -0.103, -0.5478), 1, None),
    ('LeftHandRing1', 'LeftInHandRing', (5.0624, 0.0, -0.8927), 1, None),
    ('LeftHandRing2', 'LeftHandRing1', (4.3923, 0.0, 0.0), 1, None),
    ('LeftHandRing3', 'LeftHandRing2', (2.8327, -0.0001, 0.0), 1, (1.4163, 0.0, 0.0)),
    ('LeftHandThumb1', 'LeftHand', (2.0791, -0.0946, 2.7863), 1, None),
    ('LeftHandThumb2', 'LeftHandThumb1', (3.9619, 0.0, 0.0), 1, None),
    ('LeftHandThumb3', 'LeftHandThumb2', (3.0072, 0.0, 0.0), 1, (1.7295, 0.0, 0.0)),
    ('Neck', 'Spine2', (18.2093, 0.0, 0.0), 1, None),
    ('Head', 'Neck', (11.0335, 0.0, 0.0), 1, (22.067, 0.0, 0.0)),
    ('RightShoulder', 'Spine2', (10.4351, 7.0401, 1.9147), 1, None),
    ('RightArm', 'RightShoulder', (13.4599, 0.0001, 0.0), 1, None),
    ('RightForeArm', 'RightArm', (26.1001, 0.0001, 0.0), 1, None),
    ('RightHand', 'RightForeArm', (28.9001, 0.0001, 0.0001), 1, None),
    ('RightInHandIndex', 'RightHand', (2.647, -0.1029, -1.6042), 1, None),
    ('RightHandIndex1', 'RightInHandIndex', (5.4271, 0.0001, -0.9569), 1, None),
    ('RightHandIndex2', 'RightHandIndex1', (4.5805, 0.0001, 0.0), 1, None),
    ('RightHandIndex3', 'RightHandIndex2', (2.8181, 0.0001, 0.0), 1, (1.4091, 0.0, 0.0)),
    ('RightInHandMiddle', 'RightHand', (2.7689, -0.1029, -0.545), 1, None),
    ('RightHandMiddle1', 'RightInHandMiddle', (5.3677, 0.0001, 0.0), 1, None),
    ('RightHandMiddle2', 'RightHandMiddle1', (4.7024, 0.0001, 0.0), 1, None),
    ('RightHandMiddle3', 'RightHandMiddle2', (3.1016, 0.0001, 0.0), 1, (1.5508, 0.0001, 0.0)),
    ('RightInHandPinky', 'RightHand', (2.4892, -0.1029, 1.4884), 1, None),
    ('RightHandPinky1', 'RightInHandPinky', (4.529, 0.0002, 1.6484), 1, None),
    ('RightHandPinky2', 'RightHandPinky1', (3.5541, 0.0, 0.0), 1, None),
    ('RightHandPinky3', 'RightHandPinky2', (2.234, 0.0001, 0.0), 1, (1.117, 0.0001, 0.0)),
    ('RightInHandRing', 'RightHand', (2.7444, -0.1029, 0.5478), 1, None),
    ('RightHandRing1', 'RightInHandRing', (5.0624, 0.0002, 0.8927), 1, None),
    ('RightHandRing2', 'RightHandRing1', (4.3922, 0.0001, 0.0), 1, None),
    ('RightHandRing3', 'RightHandRing2', (2.8327, 0.0001, 0.0), 1, (1.4163, 0.0, 0.0)),
    ('RightHandThumb1', 'RightHand', (2.0791, -0.0945, -2.7863), 1, None),
    ('RightHandThumb2', 'RightHandThumb1', (3.9619, 0.0001, 0.0), 1, None),
    ('RightHandThumb3', 'RightHandThumb2', (3.0072, 0.0001, 0.0), 1, (1.7295, 0.0, 0.0)),
    ('LeftUpLeg', 'Hips', (8.1, 0.0, 0.0), 1, None),
    ('LeftLeg', 'LeftUpLeg', (43.2, 0.0, 0.0), 1, None),
    ('LeftFoot', 'LeftLeg', (43.3, 0.0, 0.0), 1, None),
    ('LeftToeBase', 'LeftFoot', (14.5727, 0.0, 0.0), 1, (7.2863, 0.0, 0.0)),
    ('RightUpLeg', 'Hips', (-8.1, 0.0, 0.0), 1, None),
    ('RightLeg', 'RightUpLeg', (43.2, 0.0, 0.0), 1, None),
    ('RightFoot', 'RightLeg', (43.3, -0.0626, 0.0), 1, None),
    ('RightToeBase', 'RightFoot', (14.5727, 0.0, 0.0), 1, (7.2864, 0.0, 0.0)),
)

#: (name, parent, OFFSET, channel set index, End Site OFFSET or None), in file order
XSENS_MVN_CHANNELS = ('Xposition Yposition Zposition Yrotation Xrotation Zrotation', 'Yrotation Xrotation Zrotation')
XSENS_MVN = (
    ('Hips', None, (0.0, 0.0, 0.0), 0, None),
    ('Chest', 'Hips', (0.0, 9.817266, -1.090808), 1, None),
    ('Chest2', 'Chest', (0.0, 10.878341, 0.0), 1, None),
    ('Chest3', 'Chest2', (0.0, 9.932046, -0.002339), 1, None),
    ('Chest4', 'Chest3', (0.0, 9.920956, -0.002341), 1, None),
    ('Neck', 'Chest4', (0.0, 13.897299, 0.0), 1, None),
    ('Head', 'Neck', (0.0, 9.237018, 0.00503), 1, (0.0, 17.155989, 0.000677)),
    ('RightCollar', 'Chest4', (-3.028356, 7.791542, 0.0), 1, None),
    ('RightShoulder', 'RightCollar', (-14.177729, 0.0, 0.0), 1, None),
    ('RightElbow', 'RightShoulder', (-30.364375, 0.0, 0.0), 1, None),
    ('RightWrist', 'RightElbow', (-24.820744, 0.0, 0.0), 1, (-18.530853, 0.0, 0.0)),
    ('LeftCollar', 'Chest4', (3.028356, 7.791542, 0.0), 1, None),
    ('LeftShoulder', 'LeftCollar', (14.177729, 0.0, 0.0), 1, None),
    ('LeftElbow', 'LeftShoulder', (30.364375, 0.0, 0.0), 1, None),
    ('LeftWrist', 'LeftElbow', (24.820744, 0.0, 0.0), 1, (18.530853, 0.0, 0.0)),
    ('RightHip', 'Hips', (-8.081064, 0.006831, -0.000759), 1, None),
    ('RightKnee', 'RightHip', (0.0, -41.932394, -0.000553), 1, None),
    ('RightAnkle', 'RightKnee', (0.0, -40.919741, -0.000931), 1, None),
    ('RightToe', 'RightAnkle', (0.0, -7.124271, 16.180034), 1, (0.0, -1.571563, 6.815722)),
    ('LeftHip', 'Hips', (8.081064, 0.00462, -0.000513), 1, None),
    ('LeftKnee', 'LeftHip', (0.0, -41.932394, -0.000553), 1, None),
    ('LeftAnkle', 'LeftKnee', (0.0, -40.919741, -0.000931), 1, None),
    ('LeftToe', 'LeftAnkle', (0.0, -7.124271, 16.180034), 1, (0.0, -1.571563, 6.815722)),
)

#: four frames of the Rokoko take (its frames 1, 2 and two from the middle, 100 fps)
ROKOKO_FRAMES = (
    "-6.2023 87.7332 -161.6986 17.0013 6.7732 5.9465 0.0000 0.0000 90.0000 0.0000 0.0000 0.0000 0.0000 "
    "-23.1850 0.0000 0.0000 0.0000 -90.0000 -39.8104 6.8771 -77.3960 -29.2518 0.0000 0.0000 0.0000 0.0000 "
    "0.0000 0.0024 1.2310 0.2171 -8.2881 0.5560 -17.9917 0.0007 0.0002 -17.9988 -0.0008 0.0000 -18.0016 "
    "0.0000 -0.0001 0.0000 -5.1372 -1.6664 -17.9253 0.0000 0.0000 -18.0001 -0.0035 -0.0010 -18.0000 "
    "0.5905 -5.8773 -5.1793 11.2007 -13.4477 -16.1482 -0.0001 -0.0003 -18.0000 0.0000 0.0000 -17.9992 "
    "0.1281 -2.7201 -2.5537 1.3567 -8.1103 -16.9813 0.0001 0.0000 -17.9991 -0.0035 -0.0011 -18.0010 "
    "-51.5734 53.9498 -31.5004 6.3507 0.3529 -6.3509 6.3509 0.3526 -6.3510 0.0000 0.0000 0.0000 23.7879 "
    "15.0347 -90.7782 180.0000 0.0000 89.9999 48.2755 5.5788 -73.4646 28.3455 0.0000 0.0000 0.0000 0.0000 "
    "0.0000 -0.0024 -1.2310 0.2171 8.2881 -0.5563 -17.9918 -0.0003 -0.0001 -17.9993 178.0982 0.6179 "
    "17.9904 0.0000 0.0000 0.0001 5.1372 1.6664 -17.9253 0.0000 0.0000 -18.0000 178.0978 0.6179 17.9897 "
    "-0.5906 5.8773 -5.1799 -11.2007 13.4479 -16.1482 -0.0002 -0.0001 -17.9992 178.0983 0.6180 17.9922 "
    "-0.1281 2.7201 -2.5536 -1.3567 8.1101 -16.9812 0.0000 0.0000 -17.9993 178.0978 0.6179 17.9904 "
    "51.5729 -53.9501 -31.5000 -6.3505 -0.3528 -6.3507 -6.3509 -0.3527 -6.3510 -3.1861 -1.0582 -88.2455 "
    "36.0193 -0.0233 0.1238 286.4078 90.0000 0.0000 1.7672 -2.1303 50.3087 -13.6570 -5.7800 -89.4969 "
    "44.6899 0.0597 -0.0962 280.6449 90.0000 0.0000 0.8503 -1.0364 50.6282",
    "-6.3048 87.6551 -161.5300 17.0647 6.8045 6.0408 0.0000 0.0000 90.0000 0.0000 0.0000 0.0000 0.0000 "
    "-23.2491 0.0000 0.0000 0.0000 -90.0000 -40.0707 7.2856 -77.3933 -29.7896 0.0000 0.0000 0.0000 0.0000 "
    "0.0000 0.0024 1.2310 0.2171 -8.2881 0.5560 -17.9917 0.0007 0.0002 -17.9988 -0.0008 0.0000 -18.0016 "
    "0.0000 -0.0001 0.0000 -5.1372 -1.6664 -17.9253 -0.0001 0.0000 -18.0001 -0.0035 -0.0010 -18.0000 "
    "0.5905 -5.8773 -5.1793 11.2007 -13.4477 -16.1482 -0.0001 -0.0003 -18.0000 0.0000 0.0000 -17.9992 "
    "0.1281 -2.7201 -2.5537 1.3567 -8.1103 -16.9812 0.0000 0.0000 -17.9990 -0.0035 -0.0011 -18.0010 "
    "-51.5735 53.9498 -31.5005 6.3507 0.3529 -6.3509 6.3509 0.3526 -6.3510 0.0000 0.0000 0.0000 23.8890 "
    "15.1756 -90.7705 180.0000 0.0000 89.9999 49.1206 5.1569 -73.1997 28.7321 0.0000 0.0000 0.0000 0.0000 "
    "0.0000 -0.0024 -1.2310 0.2172 8.2881 -0.5563 -17.9918 -0.0003 -0.0001 -17.9993 178.0982 0.6179 "
    "17.9904 -0.0001 0.0000 0.0001 5.1372 1.6664 -17.9253 0.0000 0.0000 -18.0000 178.0978 0.6179 17.9897 "
    "-0.5906 5.8773 -5.1799 -11.2007 13.4479 -16.1469 -0.0002 -0.0001 -17.9992 178.0983 0.6180 17.9922 "
    "-0.1281 2.7201 -2.5536 -1.3568 8.1101 -16.9812 0.0000 0.0000 -17.9993 178.0978 0.6179 17.9904 "
    "51.5729 -53.9501 -31.5001 -6.3505 -0.3528 -6.3507 -6.3510 -0.3527 -6.3509 -3.2034 -1.7419 -87.9813 "
    "36.7955 -0.0244 0.1248 286.1530 90.0000 0.0000 1.7927 -2.1661 50.3737 -13.5930 -6.0507 -89.1752 "
    "45.0140 0.0595 -0.0948 280.5720 90.0000 0.0000 0.9267 -1.1303 50.6491",
    "-15.6080 111.5738 -145.3027 21.1476 9.0959 9.8574 0.0000 0.0000 90.0000 0.0000 0.0000 0.0000 0.0000 "
    "-28.4051 0.0000 0.0000 0.0000 -90.0000 -75.2616 20.4507 -75.2440 -50.3383 0.0000 0.0000 0.0000 "
    "0.0000 0.0000 0.0024 1.2310 0.2171 -8.2881 0.5560 -17.9917 0.0007 0.0002 -17.9988 -0.0008 0.0000 "
    "-18.0016 0.0000 -0.0001 0.0000 -5.1372 -1.6664 -17.9253 0.0000 0.0000 -18.0001 -0.0035 -0.0010 "
    "-18.0000 0.5905 -5.8773 -5.1793 11.2007 -13.4477 -16.1482 -0.0001 -0.0003 -18.0000 0.0000 0.0000 "
    "-17.9993 0.1281 -2.7201 -2.5537 1.3567 -8.1103 -16.9813 0.0001 0.0001 -17.9990 -0.0035 -0.0011 "
    "-18.0010 -51.5735 53.9499 -31.5005 6.3507 0.3529 -6.3509 6.3509 0.3526 -6.3510 0.0000 0.0000 0.0000 "
    "21.9457 20.4060 -94.8971 180.0000 0.0000 89.9999 72.2574 -9.6424 -58.1641 42.6395 0.0000 0.0000 "
    "0.0000 0.0000 0.0000 -0.0024 -1.2310 0.2172 8.2881 -0.5563 -17.9918 -0.0003 -0.0001 -17.9993 "
    "178.0982 0.6179 17.9904 -0.0001 0.0000 0.0001 5.1372 1.6664 -17.9253 0.0000 0.0000 -18.0000 178.0978 "
    "0.6179 17.9897 -0.5906 5.8773 -5.1799 -11.2007 13.4479 -16.1470 -0.0002 -0.0001 -17.9992 178.0983 "
    "0.6180 17.9922 -0.1281 2.7201 -2.5536 -1.3567 8.1101 -16.9812 0.0000 0.0000 -17.9993 178.0978 0.6179 "
    "17.9904 51.5729 -53.9501 -31.5001 -6.3505 -0.3528 -6.3507 -6.3509 -0.3527 -6.3509 -51.2338 -59.6082 "
    "-8.7788 92.0521 0.0001 0.0826 295.2681 90.0000 0.0000 6.2043 -2.5695 22.4113 -33.9104 -13.6081 "
    "-90.6194 37.0531 0.0000 0.0000 295.3508 90.0000 0.0000 0.4078 -0.1751 23.2353",
    "-15.1187 102.3914 -146.4455 24.1140 11.4948 12.1010 0.0000 0.0000 90.0000 0.0000 0.0000 0.0000 "
    "0.0000 -27.3805 0.0000 0.0000 0.0000 -90.0000 -79.1739 9.0206 -75.9983 -26.4670 0.0000 0.0000 0.0000 "
    "0.0000 0.0000 0.0024 1.2310 0.2171 -8.2881 0.5561 -17.9917 0.0007 0.0002 -17.9988 -0.0008 0.0000 "
    "-18.0016 0.0000 -0.0001 0.0000 -5.1372 -1.6664 -17.9253 0.0000 0.0000 -18.0001 -0.0035 -0.0010 "
    "-18.0000 0.5905 -5.8773 -5.1793 11.2007 -13.4477 -16.1482 -0.0001 -0.0003 -18.0000 0.0000 0.0000 "
    "-17.9993 0.1281 -2.7201 -2.5536 1.3567 -8.1103 -16.9813 0.0001 0.0000 -17.9990 -0.0035 -0.0011 "
    "-18.0010 -51.5734 53.9498 -31.5004 6.3507 0.3529 -6.3509 6.3509 0.3527 -6.3510 0.0000 0.0000 0.0000 "
    "24.8031 19.4248 -96.1322 180.0000 0.0000 89.9999 51.0489 7.1814 -65.5368 23.9063 0.2153 -1.2217 "
    "0.0000 0.0000 0.0000 -0.0024 -1.2310 0.2172 8.2881 -0.5563 -17.9918 -0.0003 -0.0001 -17.9993 "
    "178.0982 0.6179 17.9904 -0.0001 0.0000 0.0001 5.1372 1.6664 -17.9253 0.0000 0.0000 -18.0000 178.0978 "
    "0.6179 17.9897 -0.5906 5.8773 -5.1799 -11.2007 13.4479 -16.1469 -0.0002 -0.0001 -17.9993 178.0983 "
    "0.6180 17.9922 -0.1281 2.7201 -2.5536 -1.3567 8.1101 -16.9812 0.0000 0.0000 -17.9993 178.0978 0.6179 "
    "17.9904 51.5729 -53.9501 -31.5001 -6.3505 -0.3527 -6.3507 -6.3509 -0.3527 -6.3509 -67.3959 -64.7139 "
    "8.4790 66.1059 0.0000 0.0826 295.2681 90.0000 0.0000 5.5778 -2.3067 22.3983 -33.9201 -8.9270 "
    "-89.9209 34.9940 0.0000 0.0000 295.3508 90.0000 0.0000 0.6106 -0.2528 22.4884",
)


def bvh_text(joints, channel_sets: Sequence[str], frames: Optional[Sequence[str]] = None, n_tpose: int = 2,
             frame_time: float = 0.01) -> str:
    """BVH text of a hierarchy from this module: its ``frames`` (text rows), or ``n_tpose`` rows of
    the zero pose (zero rotations, positions = the OFFSETs)."""
    children = {}
    for row in joints:
        children.setdefault(row[1], []).append(row)
    out, zero = ["HIERARCHY"], []

    def emit(row, depth):
        name, parent, off, ch, end = row
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}")
        out.append(pad + "{")
        out.append(f"{pad}  OFFSET {off[0]:.4f} {off[1]:.4f} {off[2]:.4f}")
        chans = channel_sets[ch].split()
        out.append(f"{pad}  CHANNELS {len(chans)} {' '.join(chans)}")
        zero.extend(off["XYZ".index(c[0].upper())] if c.lower().endswith("position") else 0.0 for c in chans)
        for c in children.get(name, []):
            emit(c, depth + 1)
        if end is not None:
            out.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET {end[0]:.4f} {end[1]:.4f} {end[2]:.4f}",
                        pad + "  }"])
        out.append(pad + "}")

    emit(children[None][0], 0)
    rows = list(frames) if frames is not None else [" ".join(f"{v:.4f}" for v in zero)] * n_tpose
    out += ["MOTION", f"Frames: {len(rows)}", f"Frame Time: {frame_time:.6f}"] + rows
    return "\n".join(out) + "\n"
