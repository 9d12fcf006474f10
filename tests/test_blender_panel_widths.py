"""Every label of the MANIKIN sidebar fits a 250 px sidebar at Resolution Scale 1.0.

Blender labels do not wrap: one too long for its place is cut in the middle ("Set Scene Ran...")
and an animator cannot tell what the checkbox does.  The panels' ``draw()`` is run on a layout
that lays its items out the way Blender 4.3 does (rows share their width, ``use_property_split``
gives the label column 40 % of the width and a checkbox's text the other 60 %, a heading takes the
label column) and each text -- given to ``prop``/``label``/``operator``, else the property's or the
operator's name -- is measured with the panel code's own text-width function (:mod:`blf`, the UI
font).  The room each kind of item leaves its text was measured on Blender 4.3's window
(tools/panel_screenshot.sh with MANIKIN_SHOT_SIDEBAR=250): the panels' content is 195 px wide in a
250 px sidebar; "Frame Range" (69 px) fits the label column, "Edited Offsets" (75 px) is cut;
"Tracker Empties" (85 px) fits beside a checkbox, "Set Scene Range" (88 px) is cut.  Sidebar
widths are kept in unscaled pixels, so at Resolution Scale 1.25 the same sidebar is 25 % wider
and its texts too: what fits at 1.0 fits there.
"""
from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")

import blender_manikin  # noqa: E402
from blender_manikin.blender import armature as arm_mod  # noqa: E402
from blender_manikin.blender import character_swivel, live_rig, writer  # noqa: E402
from blender_manikin.core import skeleton as sk  # noqa: E402

from blender_util import fresh_scene  # noqa: E402

SIDEBAR = 250
CONTENT = SIDEBAR - 55          # the tab strip and the panel's margins (measured, Blender 4.3)
LABEL_COLUMN = 0.4              # Blender's property split
LABEL_PAD = 8                   # right-aligned label: its margins in the label column
CHECK = 30                      # a checkbox and the margins of the text beside it
TEXT_PAD = 10                   # a label's or button's margins
ICON = 20
BOX_PAD = 10
LIST_ROW = SIDEBAR - 84         # a UIList row (less its scroll bar; measured: 166 px at 250)


class MeasuredLayout:
    """A stand-in for a panel's ``layout`` that keeps what is drawn, and how, to be laid out
    afterwards at a given width (:meth:`texts`)."""

    def __init__(self, kind="column", split=False, heading="", factor=0.5):
        self.kind, self.use_property_split, self.heading, self.factor = kind, split, heading, factor
        self.items = []
        self.use_property_decorate = False
        self.active = self.enabled = True
        self.alert, self.scale_y, self.alignment = False, 1.0, 'EXPAND'

    def _child(self, kind, heading="", factor=0.5):
        # the items of a row headed in a split layout are drawn whole (the heading has the label column)
        split = self.use_property_split and not (self.kind == "row" and self.heading)
        child = MeasuredLayout(kind, split, heading, factor)
        self.items.append(("layout", child))
        return child

    def row(self, heading="", align=False, **k):
        return self._child("row", heading)

    def column(self, heading="", align=False, **k):
        return self._child("column", heading)

    def box(self):
        return self._child("box")

    def split(self, factor=0.5, **k):
        return self._child("split", factor=factor)

    def prop(self, data, name, text=None, icon='NONE', expand=False, **k):
        if name.startswith('["'):           # a custom property: its name is the text given
            kind, label, enum = "FLOAT", text, ()
        else:
            rna = data.bl_rna.properties[name]
            kind, label = rna.type, rna.name if text is None else text
            enum = [i.name for i in rna.enum_items] if kind == 'ENUM' and expand else ()
        self.items.append(("prop", kind, label, icon != 'NONE', enum))

    def prop_search(self, data, name, search_data, search_name, text=None, icon='NONE', **k):
        label = data.bl_rna.properties[name].name if text is None else text
        self.items.append(("prop", "STRING", label, False, ()))

    def operator(self, idname, text=None, icon='NONE', **k):
        mod, name = idname.split(".")
        op = getattr(getattr(bpy.ops, mod), name)
        label = op.get_rna_type().name if text is None else text
        self.items.append(("operator", label, icon != 'NONE'))
        return SimpleNamespace()

    def label(self, text="", icon='NONE', **k):
        self.items.append(("label", text, icon != 'NONE'))

    def template_list(self, *a, **k):
        pass

    def separator(self, factor=1.0, **k):
        self.items.append(("separator", factor))

    # -- laying out ------------------------------------------------------------------------
    def texts(self, width, out, where="", measure=None):
        """``out`` gets ``(text, room_px, where)`` for each text drawn at ``width`` pixels."""
        heading = self.heading
        if heading and self.use_property_split:
            out.append((heading, LABEL_COLUMN * width - LABEL_PAD, where + " (heading)"))
        items = [it for it in self.items if it[0] != "separator"]
        if self.kind == "row":
            # icon-only buttons are one unit wide, separators indent
            def bare(it):           # an icon-only button or a checkbox without text: one unit
                return (it[0] == "operator" and not it[1]) or (it[0] == "prop" and it[1] == 'BOOLEAN'
                                                                 and not it[2])
            fixed = sum(ICON for it in items if bare(it))
            fixed += sum(10 * it[1] for it in self.items if it[0] == "separator")
            if heading and self.use_property_split:      # the heading has the label column
                width, split = (1 - LABEL_COLUMN) * width, False
            else:
                split = self.use_property_split
            # a sub-layout aligned left or right is as wide as its content; the rest share equally
            # (as Blender 4.3 drew "Key Swivel | Reset" and "Smooth Sw... | Reset All")
            sized = [it[0] == "layout" and it[1].alignment != 'EXPAND' for it in items]
            fixed += sum(_asks(it, measure) for it, f in zip(items, sized) if f)
            n = sum(1 for it, f in zip(items, sized) if not f and not bare(it))
            widths = [ICON if bare(it) else _asks(it, measure) if f else
                      (width - fixed) / max(1, n) for it, f in zip(items, sized)]
        elif self.kind == "split":
            split = self.use_property_split
            rest = (1 - self.factor) * width / max(1, len(items) - 1)
            widths = [self.factor * width] + [rest] * (len(items) - 1)
        else:
            split = self.use_property_split
            inner = width - BOX_PAD if self.kind == "box" else width
            widths = [inner] * len(items)
        row_width = width       # a split row's props: the label column is 40 % of the whole row
        for it, w in zip(items, widths):
            if it[0] == "layout":
                it[1].texts(w, out, where, measure)
            elif it[0] == "prop":
                _, kind, label, icon, enum = it
                if enum:
                    out.extend((e, w / len(enum) - TEXT_PAD, where + " (expanded)") for e in enum)
                elif not label:
                    continue
                elif kind == 'BOOLEAN':
                    room = (1 - LABEL_COLUMN) * w - CHECK if split else w - CHECK
                    out.append((label, room, where + " (checkbox)"))
                elif split:
                    column = LABEL_COLUMN * (row_width if self.kind == "row" else w)
                    out.append((label, column - LABEL_PAD, where + " (label column)"))
                else:                            # the label inside its field, beside the value
                    out.append((label, w / 2 - TEXT_PAD, where + " (in its field)"))
            elif it[0] in ("operator", "label"):
                _, label, icon = it
                if label:
                    out.append((label, w - TEXT_PAD - (ICON if icon else 0), where + f" ({it[0]})"))
        return out


def _asks(item, measure):
    """The width a row item asks for: its text, icon and margins (a value field: 3 units more)."""
    if item[0] == "layout":
        if item[1].kind == "row":
            return sum(_asks(it, measure) for it in item[1].items if it[0] != "separator")
        return max((_asks(it, measure) for it in item[1].items if it[0] != "separator"), default=0)
    if item[0] == "prop" and item[1] == 'BOOLEAN' and not item[2]:
        return ICON                             # a bare checkbox
    if item[0] == "prop":
        return measure(item[2] or "") + TEXT_PAD + 3 * ICON
    return measure(item[1]) + TEXT_PAD + (ICON if item[2] else 0)


@pytest.fixture
def addon():
    fresh_scene()
    blender_manikin.register()
    yield bpy.context.scene.manikin
    blender_manikin.unregister()


def _context(sidebar=SIDEBAR, **k):
    prefs = bpy.context.preferences
    return SimpleNamespace(scene=bpy.context.scene, region=SimpleNamespace(width=sidebar), preferences=prefs,
                           active_object=k.get("active_object", bpy.context.active_object))


def _draw(cls, context, where):
    layout = MeasuredLayout()
    cls.draw(SimpleNamespace(layout=layout), context)
    from blender_manikin.panels import main as panels
    return layout.texts(context.region.width - 55, [], where, panels._text_measure(context, 1.0))


def _panel_states(s):
    """Every panel in each state a user can bring it to: ``(panel class, context, where)``."""
    from blender_manikin.panels import main as panels
    scene = bpy.context.scene
    rig = bpy.data.objects.new("tracker_rig", bpy.data.armatures.new("tracker_rig"))
    scene.collection.objects.link(rig)
    character = bpy.data.objects.new("character", bpy.data.armatures.new("character"))
    scene.collection.objects.link(character)
    reports = ("168 frames at 24 fps; model head and hands (manikin_s.onnx); check the left hand: out of "
               "reach for 1.2 s (frames 40-68); offsets openxr_generic (auto: from the file)",
               "Solve failed: the recording /tmp/take.csv, line 12: column 'head_qw' is not a number")
    for source in ('FILE', 'SCENE', 'KEYPOINTS'):
        s.source = source
        for kp_from in ('FILE', 'OBJECTS'):
            s.keypoint_from = kp_from
            s.use_keypoint_rate = True
            s.left_hand.object = rig
            for model in ('AUTO', 'FILE'):
                s.model = model
                s.smoothing_mode = 'WINDOW'
                for report in reports:
                    s.last_report = report
                    yield panels.MANIKIN_PT_solve, f"Solve ({source}, {kp_from}, {model})"
            for cal in ('AUTO', 'TPOSE', 'MEASURE'):
                s.calibration = cal
                for floor in ('ZERO', 'OFFSET', 'PERFORMER'):
                    s.floor_mode = floor
                    if panels.MANIKIN_PT_calibration.poll(bpy.context):
                        yield panels.MANIKIN_PT_calibration, f"Calibration ({source}, {cal}, {floor})"
            yield panels.MANIKIN_PT_output, f"Frames and Output ({source}, {kp_from})"
    for target in (None, character):
        s.retarget_target = target
        for bone_map in ('AUTO', 'FILE'):
            s.retarget_map = bone_map
            s.retarget_bone_map_source = "Mixamo preset"
            yield panels.MANIKIN_PT_retarget, f"Retarget to Character ({target and target.name}, {bone_map})"
        for fmt in ('FBX', 'GLB'):
            s.export_format = fmt
            yield panels.MANIKIN_PT_export, f"Export ({target and target.name}, {fmt})"


def _bone_map_rows(s, sidebar=SIDEBAR):
    """The bone map list's rows, one per joint of the body model, at a ``sidebar`` px sidebar."""
    from blender_manikin.panels import main as panels
    measure = panels._text_measure(_context(), 1.0)
    s.retarget_target = None
    s.retarget_bone_map.clear()
    for joint in sk.JOINT_NAMES:
        s.retarget_bone_map.add().name = joint
    out = []
    for item in s.retarget_bone_map:
        layout = MeasuredLayout()
        panels.MANIKIN_UL_bone_map.draw_item(None, _context(sidebar), layout, s, item, 0, s,
                                             "retarget_bone_map_index")
        layout.texts(sidebar - 84, out, "Bone map list", measure)
    assert len(out) == len(sk.JOINT_NAMES)
    return out


def _swivel_states(monkeypatch, sidebar=SIDEBAR):
    """The Swivel & Posing panel on a solved armature: plain FK, live, and a character's rig."""
    from blender_manikin.panels import swivel_panel
    obj = bpy.data.objects.new("MANIKIN_body", bpy.data.armatures.new("MANIKIN_body"))
    bpy.context.scene.collection.objects.link(obj)
    obj[arm_mod.PROP_BODY] = "{}"
    for limb in sk.LIMB_NAMES:
        obj[writer.SWIVEL_PROPS[limb]] = 0.5
        obj[live_rig.SOLVED_PROPS[limb]] = -0.25
    for live, character in ((False, False), (True, False), (False, True)):
        monkeypatch.setattr(live_rig, "is_live_rig", lambda o, live=live: live)
        monkeypatch.setattr(character_swivel, "is_character_rig", lambda o, c=character: c)
        yield swivel_panel.MANIKIN_PT_swivel, _context(sidebar, active_object=obj), \
            f"Swivel & Posing (live={live}, character={character})"


def _cut(s, monkeypatch, sidebar):
    """The texts cut at a ``sidebar`` px sidebar (scale 1.0), each ``(text, where)``, of the
    ``texts_drawn`` (at least 100: every panel in every state was drawn)."""
    from blender_manikin.panels import main as panels
    measure = panels._text_measure(_context(), 1.0)
    assert measure("MANIKIN") != len("MANIKIN") * 6.2, "blf could not measure the UI font"
    texts = []
    for cls, where in _panel_states(s):
        texts += _draw(cls, _context(sidebar), where)
    for cls, context, where in _swivel_states(monkeypatch, sidebar):
        texts += _draw(cls, context, where)
    texts += _bone_map_rows(s, sidebar)
    assert len(texts) > 100
    return sorted({(f"{text!r} ({measure(text):.0f} px in {room:.0f} px): {where.split(' (')[0]}"
                    f"{where[where.rfind(' ('):]}") for text, room, where in texts if measure(text) > room})


def test_every_label_fits_a_250_px_sidebar(addon, monkeypatch):
    cut = _cut(addon, monkeypatch, SIDEBAR)
    assert not cut, "cut at a 250 px sidebar:\n" + "\n".join(cut)


@pytest.mark.parametrize("sidebar", [230])
def test_the_summary_lines_fit_a_narrower_sidebar(addon, monkeypatch, sidebar):
    """The solve summary and the swivel hints are wrapped to the sidebar (:func:`wrapped`): no
    line of theirs is cut even where a setting's name is (Blender's own panels cut those too)."""
    cut = [c for c in _cut(addon, monkeypatch, sidebar) if c.endswith("(label)") and not c.endswith(
        "Bone map list (label)")]
    assert not cut, f"wrapped lines cut at a {sidebar} px sidebar:\n" + "\n".join(cut)


def test_the_layout_model_cuts_what_blender_cuts():
    """The room the model leaves, checked against what Blender 4.3 drew at 250 px (the measured
    texts above): it must cut "Set Scene Range" and "Edited Offsets", and keep "Tracker Empties"
    and "Frame Range" whole; a model that cut nothing, or everything, would fail here."""
    from blender_manikin.panels import main as panels
    measure = panels._text_measure(_context(), 1.0)
    layout = MeasuredLayout(split=True)
    settings = SimpleNamespace(bl_rna=SimpleNamespace(properties={
        "a": SimpleNamespace(type='BOOLEAN', name="Set Scene Range"),
        "b": SimpleNamespace(type='BOOLEAN', name="Tracker Empties"),
        "c": SimpleNamespace(type='POINTER', name="Edited Offsets"),
        "d": SimpleNamespace(type='POINTER', name="Frame Range")}))
    for name in "abcd":
        layout.prop(settings, name)
    fits = {text: measure(text) <= room for text, room, _ in layout.texts(CONTENT, [], "", measure)}
    assert fits == {"Set Scene Range": False, "Tracker Empties": True, "Edited Offsets": False,
                    "Frame Range": True}
    # the bone map list's joint column at the split of 0.4 Blender drew: "Right Kn...", "Left Knee"
    fits = {}
    for joint in ("Right Knee", "Left Knee"):
        row = MeasuredLayout()
        row.split(factor=0.4).label(text=joint)
        fits.update({text: measure(text) <= room for text, room, _ in row.texts(LIST_ROW, [], "", measure)})
    assert fits == {"Right Knee": False, "Left Knee": True}
