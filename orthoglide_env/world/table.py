"""The sizes of the real lab's effects: one table, each number with its source.

Each row is one parameter of one effect.  Under the ``lab`` conditions (a
temperature-controlled room, a well-kept machine: C3 screws, preloaded nuts, good
instruments) and the ``workshop`` ones (a shop floor, an ordinary machine: C5 screws,
precision nuts) a machine's value is drawn uniformly in the row's range; a ``signed``
row then takes a random sign.  A range whose ends are equal is a fixed value.  The
docs/conditions.md shows this table (``orthoglide conditions`` prints it).

Positions along a drive are measured from the back end of its travel (``rho_min``, where
the screw's fixed bearing is assumed to be); the stroke is ``rho_max - rho_min``.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Size:
    """One parameter: its range under each condition, unit, how it is drawn, source."""

    lab: tuple[float, float]
    workshop: tuple[float, float]
    unit: str
    meaning: str
    source: str
    signed: bool = False

    def at(self, condition: str) -> tuple[float, float]:
        """The range under ``condition`` (``lab`` or ``workshop``)."""
        return self.lab if condition == "lab" else self.workshop


EFFECTS: dict[str, dict[str, Size]] = {
    "lead": {
        "scale": Size((0, 12), (0, 23), "um", "travel deviation at the stroke's end "
                      "(linear part)", "ISO 3408-3 e_p, useful travel <= 315 mm: C3 12, "
                      "C5 23 um", signed=True),
        "curve": Size((0, 8), (0, 18), "um", "peak-to-peak of a smooth curve about the "
                      "mean line (two sine terms over the stroke)",
                      "ISO 3408-3 v_300p: C3 8, C5 18 um"),
        "periodic": Size((0, 6), (0, 8), "um", "peak-to-peak within one screw revolution, "
                         "random phase", "ISO 3408-3 v_2pi p: C3 6, C5 8 um"),
        "screw_lead": Size((5, 5), (5, 5), "mm", "the screw's lead (the periodic error's "
                           "period)", "assumption: a 5 mm lead, usual for a 16 mm "
                           "precision screw"),
    },
    "backlash": {
        "lost_motion": Size((0, 5), (5, 15), "um", "per axis: the carriage lags the "
                            "command by half of it in the direction of the last move",
                            "lab: a preloaded nut's elastic lost motion (assumption); "
                            "workshop: precision nuts 5-15 um (ball screw catalogues)"),
    },
    "warmup": {
        "amplitude": Size((10, 20), (20, 30), "um", "screw growth at the stroke's far end "
                          "once warm, proportional to the distance from the bearing",
                          "assumption: 10-30 um; a semi-closed-loop axis drifted 44 um on a "
                          "test part that a linear encoder removed"),
        "time_constant": Size((20, 40), (20, 40), "min", "exponential warm-up from the "
                              "lab clock's 0 (the drives are switched on at reset)",
                              "assumption: 20-40 min"),
    },
    "room": {
        "offset": Size((0, 0.5), (0, 3), "K", "room temperature at reset minus the 20 C "
                       "reference", "ISO 1 (reference 20 C); lab +-0.5 K, workshop +-3 K "
                       "(assumption)", signed=True),
        "drift": Size((0.3, 0.3), (1, 1), "K/h", "steady drift of the room",
                      "about 0.3 K/h for a controlled room, 1 K/h for a shop (assumption)",
                      signed=True),
        "walk": Size((0.1, 0.1), (0.3, 0.3), "K/sqrt(h)", "a slow random walk about the "
                     "drift (8 smooth modes over 8 h)", "assumption"),
        "expansion": Size((11.5, 11.5), (11.5, 11.5), "um/(m K)", "the machine (steel) "
                          "grows about the world origin with the room", "steel "
                          "11.5-12 um/(m K) (handbook value)"),
    },
    "dial": {
        "range": Size((0, 8), (0, 10), "um", "peak-to-peak of the indicator's error over "
                      "its whole travel (half a sine over the travel)", "ISO 463 / "
                      "JIS B 7503: 15 um over the range, 9 um any half revolution"),
        "revolution": Size((0, 4), (0, 5), "um", "peak-to-peak of the error that repeats "
                           "every revolution (1 mm)", "ISO 463 / JIS B 7503: 10 um any "
                           "revolution, 5 um any 0.1 mm"),
        "retrace": Size((0, 2), (0, 3), "um", "hysteresis: the reading differs by it "
                        "between the plunger going in and out", "ISO 463 / JIS B 7503: "
                        "retrace error 3 um"),
        "digital_range": Size((0, 3), (0, 3), "um", "a digital indicator's error over its "
                              "whole travel (half a sine; no revolution error: no gear "
                              "train), with the retrace above", "digital indicator "
                              "datasheets: 1 um resolution, accuracy about 3 um"),
        "digital_end": Size((0.2, 0.2), (0.2, 0.2), "mm", "the last part of a digital "
                            "indicator's stroke at either end, where readings scatter more",
                            "digital indicator datasheets: no repeatability guarantee "
                            "within the last 0.2 mm"),
        "digital_end_sigma": Size((3, 3), (5, 5), "um", "a reading's extra scatter there "
                                  "(added to the gauge sigma)", "assumption: the stated "
                                  "accuracy, and more on a shop floor"),
        "force_rest": Size((0.6, 0.6), (0.6, 0.6), "N", "measuring force with the plunger "
                           "out", "assumption from catalogue indicators"),
        "force_full": Size((1.5, 1.5), (1.5, 1.5), "N", "measuring force with the plunger "
                           "fully in (linear between)", "JIS B 7503:2017: at most 2 N"),
    },
    "stands": {
        "creep": Size((0, 2), (0, 5), "um", "a magnetic stand's settling after each "
                      "mounting, along the measuring axis", "assumption: a few um over "
                      "minutes", signed=True),
        "creep_time": Size((2, 5), (2, 5), "min", "its exponential time constant",
                           "assumption"),
        "give": Size((0.5, 0.5), (0.5, 0.5), "um/N", "the stand yields under the gauge's "
                     "force", "assumption"),
        "thermal": Size((2, 3.5), (2, 3.5), "um/K", "a stand's arm grows with the room, "
                        "along the measuring axis", "200-300 mm steel arm: 2-3.5 um/K",
                        signed=True),
    },
    "compliance": {
        "actuator": Size((0.03, 0.03), (0.05, 0.05), "um/N", "axial compliance of each "
                         "drive (screw, nut, bearings)", "assumption: 20-33 N/um, a "
                         "16 mm screw's axial stiffness"),
        "weight": Size((30, 30), (30, 30), "N", "weight of the platform and the legs' "
                       "moving share, along -z", "assumption: about 3 kg"),
        "bar_modulus": Size((210, 210), (210, 210), "GPa", "Young's modulus of the bars "
                            "(solid, the design's bar_section), bent by the gauge's force "
                            "between their hinges", "steel: 210 GPa"),
    },
    "thermometer": {
        "tolerance": Size((0, 0.19), (0, 0.19), "K", "the room thermometer's error (a lab "
                          "with --thermometer): a fixed offset of the lab's",
                          "IEC 60751 class A Pt100: +-(0.15 + 0.002 abs(t)) C, 0.19 K at "
                          "20 C", signed=True),
        "resolution": Size((0.01, 0.01), (0.01, 0.01), "K", "its readings are rounded to "
                           "it", "assumption: a Pt100 logger's 0.01 K display"),
    },
    "tracker": {
        "distance": Size((10, 10), (10, 10), "um", "MPE along the line of sight, plus "
                         "0.3 um/m; a reading's sigma is half the MPE", "laser tracker "
                         "datasheets (ISO 10360-10): +-(10 um + 0.3 um/m)"),
        "transverse": Size((15, 15), (15, 15), "um", "MPE across the line of sight, plus "
                           "6 um/m; sigma half of it", "datasheets: +-(15 um + 6 um/m)"),
    },
}

#: The per-metre parts of the tracker's MPE (um/m), beside the table's constant parts.
TRACKER_MPE_PER_M: dict[str, float] = {"distance": 0.3, "transverse": 6.0}

#: The lab's length reference (``reference`` slots, a lab built with ``reference=True``):
#: one steel gauge block of this nominal length (mm), across which the platform travels
#: toward a face's stand.  An assumption: the prototype's carriages reach 100 mm back from
#: Zero, and 50 mm is a common single block.
REFERENCE_LENGTH_MM: float = 50.0
#: The block's deviation from its nominal length, drawn once per lab under ``lab`` or
#: ``workshop`` (exact under ``ideal``).  Being steel at the room's temperature it grows
#: with the machine.
REFERENCE_DEVIATION: Size = Size(
    (0, 0.20), (0, 0.80), "um", "the gauge block's length minus its nominal length",
    "ISO 3650 (DIN 861) limit deviation of a 25-50 mm block: grade 0 +-0.20 um (lab), "
    "grade 2 +-0.80 um (workshop)", signed=True)

#: The instruments a lab may own beyond its dial gauges, and their own errors, drawn per
#: lab under ``lab`` or ``workshop`` (an ideal world's instruments have their noise only).
#: Kept apart from :data:`EFFECTS`: an instrument's errors act where the lab owns it,
#: whatever effects the world has.
INSTRUMENT_ERRORS: dict[str, dict[str, Size]] = {
    "interferometer": {
        "laser": Size((0.1, 0.1), (0.1, 0.1), "ppm", "the laser's own accuracy (vacuum "
                      "wavelength): a scale error of every displacement read, either sign",
                      "HP 5528A User's Guide, error budget worksheet step 7: 0.1 ppm",
                      signed=True),
        "air": Size((0, 1.5), (0, 1.5), "ppm", "the air compensation's error (the index of "
                    "air from the air sensor): a scale error per lab", "HP 5528A User's "
                    "Guide, worksheet step 4b: 1.5 ppm with the air sensor (1 ppm per 1 K, "
                    "2.5 mmHg or about 80 % RH, section 19)", signed=True),
        "material_sensor": Size((0, 0.1), (0, 0.1), "K", "the material temperature sensor's "
                                "error: the machine's expansion is compensated from it, so "
                                "it leaves (steel's coefficient) x (this) as a scale error",
                                "HP 10757 material sensor: +-0.10 C", signed=True),
        "alignment": Size((0, 0.2), (0, 0.5), "mrad", "angle between the beam and the "
                          "carriage's travel after alignment: the reading is short by "
                          "1 - cos of it", "assumption: an aligned beam within 0.2 mrad "
                          "(lab) or 0.5 mrad (workshop); cosine error per HP 5528A "
                          "section 6"),
        "noise": Size((0.1, 0.1), (0.3, 0.3), "um", "a reading's scatter (standard "
                      "deviation): air turbulence, vibration and the carriage's settling, "
                      "averaged over the dwell", "assumption: 1 nm resolution (XL-80 "
                      "datasheet, secondary) but 0.1 um in a still room, 0.3 um on a shop "
                      "floor"),
    },
    "ballbar": {
        "accuracy": Size((0.7, 0.7), (0.7, 0.7), "um", "the bar's constant accuracy at "
                         "20 C: a reading's error within it (sigma half of it, as the "
                         "tracker's MPE is taken), besides the part that grows with the "
                         "reading", "Renishaw QC20-W ballbar specification: accuracy "
                         "+-(0.7 + 0.3 % of the reading) um at 20 C (not yet checked "
                         "against the sheet's current issue)"),
        "scale": Size((0, 0.3), (0, 0.3), "%", "the transducer's scale error: the part of "
                      "the accuracy that grows with the reading, a factor per lab",
                      "Renishaw QC20-W ballbar specification: 0.3 % of the reading",
                      signed=True),
        "resolution": Size((0.1, 0.1), (0.1, 0.1), "um", "a reading is rounded to it",
                           "Renishaw QC20-W ballbar specification: sensor resolution "
                           "0.1 um"),
        "travel": Size((1.0, 1.0), (1.0, 1.0), "mm", "the bar reads within +- this of its "
                       "nominal length; a move the nominal machine puts outside it while "
                       "the bar is in is refused", "Renishaw QC20-W ballbar "
                       "specification: measurement range +-1.0 mm"),
        "centring": Size((0, 5), (0, 10), "um", "the pivot's centre ball against the TCP "
                         "where it was centred, per coordinate (a fit takes the centre as "
                         "unknown: ISO 230-4 removes the centring error)", "assumption: "
                         "a magnetic centre mount set against the tool cup by hand",
                         signed=True),
        "expansion": Size((11.5, 11.5), (11.5, 11.5), "um/(m K)", "the bar's expansion: "
                          "the same as the machine's, so the room's uniform growth cancels "
                          "on a reading", "assumption: a steel bar (the machine: "
                          "steel 11.5-12 um/(m K))"),
    },
    "step-gauge": {
        "calibration": Size((0.2, 0.2), (0.2, 0.2), "um", "the constant part of the "
                            "calibration's expanded uncertainty U of each face's position from "
                            "face 0: what each face truly lies off its certificate's value is "
                            "drawn once per gauge, normal with sigma U / 2 (k = 2 assumed)",
                            "KOBA-step (Kolb & Baumann): U = 0.2 um + 0.5e-6 L ('KOBA-step "
                            "and ISO 10360 requirements', item 6; catalogue 6100/E/01/2009)"),
        "calibration_length": Size((0.5, 0.5), (0.5, 0.5), "um/m", "the part of U that grows "
                                   "with a face's distance L from face 0: a scale error of the "
                                   "gauge's faces, drawn once per gauge, normal with sigma "
                                   "half of it", "KOBA-step: U = 0.2 um + 0.5e-6 L"),
        "expansion": Size((11.3, 11.3), (11.3, 11.3), "um/(m K)", "the gauge's expansion: its "
                          "faces grow from face 0 with the room; the lab takes them, and the "
                          "machine's growth with the steel's coefficient, to 20 C at the "
                          "thermometer's reading (at 20 C without one)",
                          "KOBA-step: coefficient of thermal expansion 11.3e-6/K ('KOBA-step "
                          "and ISO 10360 requirements', item 11)"),
        "misalignment": Size((0, 1.0), (0, 2.0), "mrad", "angle between the gauge's line and "
                             "the world axis it is laid along, per set-up: the faces' normal "
                             "is tilted by it, so a step reads long by 1/cos - 1 of it "
                             "(cosine error) and a move across the line by its sine",
                             "assumption: laid against a square and checked with an "
                             "indicator over its length, 0.1-0.3 mm over 140 mm"),
        "probe": Size((0.2, 0.2), (0.3, 0.3), "um", "a reading's scatter (standard "
                      "deviation): the probe's repeatability on a face",
                      "assumption: an electronic length probe of 0.1 um resolution; 0.2 um in "
                      "a still room, 0.3 um on a shop floor"),
        "resolution": Size((0.1, 0.1), (0.1, 0.1), "um", "a reading is rounded to it",
                           "assumption: an electronic length probe's 0.1 um display"),
        "range": Size((0.5, 0.5), (0.5, 0.5), "mm", "the probe reads a face within +- this "
                      "of where it touches face 0: a move while the gauge is set up must "
                      "bring the nominal TCP within it of a face along the gauge",
                      "assumption: an electronic length probe's +-0.5 mm"),
        "across": Size((2.0, 2.0), (2.0, 2.0), "mm", "how far across the gauge's line the "
                       "probe may touch a face", "assumption: a face's half-height less the "
                       "probe tip's radius"),
    },
}

#: The step gauge's faces: their spacing (mm) and how many a gauge has (face 0 to face
#: ``STEP_GAUGE_FACES - 1``, the last ``(STEP_GAUGE_FACES - 1) * STEP_GAUGE_PITCH_MM`` from
#: the first).
STEP_GAUGE_PITCH_MM: float = 20.0
STEP_GAUGE_FACES: int = 9
#: Where they come from (``orthoglide conditions`` and docs/instruments.md show it).
STEP_GAUGE_SOURCE: str = ("KOBA-step: standard distance 20 mm ('KOBA-step and ISO 10360 "
                          "requirements', item 4); 9 faces (160 mm) is an assumption: a "
                          "gauge as long as the prototype's travel along a world axis "
                          "through Zero")

#: The bar lengths (mm) a lab's ballbar can be set up with: the nominal bar, its radius
#: halved with a small-circle set-up, and one extension.  On the prototype a whole circle
#: fits at 50 mm only; 100 and 150 mm bars read arcs.
BALLBAR_LENGTHS_MM: tuple[float, ...] = (50.0, 100.0, 150.0)
#: Where the lengths come from (``orthoglide conditions`` and docs/instruments.md show it).
BALLBAR_LENGTHS_SOURCE: str = ("Renishaw QC20-W: nominal length 100 mm, extension bars of "
                               "50, 150 and 300 mm; the 50 mm radius is an assumption (a "
                               "small-circle set-up)")

#: Closed-loop drives (conditions with ``drives="scales"``): a linear scale beside each
#: drive reads the carriage, so the screw's lead error, its periodic error, its growth
#: as it warms and the nut's reversal no longer reach the carriage (HEIDENHAIN, "Exposed
#: linear encoders", introduction; the feed-transmission accuracy article).  What is
#: left is the scale's own error and its expansion.
SCALES: dict[str, Size] = {
    "grade": Size((0, 3), (0, 5), "um", "the scale's error along the stroke, linear, at "
                  "the stroke's end: its accuracy grade +-a bounds the error over any 1 m, "
                  "and the 160 mm stroke lies in one", "HEIDENHAIN sealed linear encoders: "
                  "grades +-3 and +-5 um (exposed LIP: +-1 um); the grade's definition: "
                  "HEIDENHAIN, 'Positionsabweichungen ueber den Messweg'", signed=True),
    "expansion": Size((8, 8), (8, 8), "um/(m K)", "the scale's expansion (glass): the "
                      "carriage follows it with the room instead of the screw's steel",
                      "assumption: about 8 ppm/K for a glass scale (the LC/LS coefficient "
                      "was not found; Invar about 1, Zerodur about 0)"),
}
#: Faults (a lab built with ``faults=``): things that go wrong in a session, each kind's
#: ``rate`` (events per hour of lab time, a Poisson process) and ``size``.  Under ``ideal``
#: conditions they take the ``lab`` column.  None of these has a sourced number here: they
#: are assumptions, set so that one hour of work meets about one of each kind asked for.
FAULTS: dict[str, dict[str, Size]] = {
    "knock": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a stand is knocked", "assumption"),
        "size": Size((0.01, 0.05), (0.02, 0.1), "mm", "its mounting moves along the "
                     "measuring axis by this, from that reading until it is re-mounted",
                     "assumption: a bump on a magnetic stand's arm, tens of um", signed=True),
    },
    "stick": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a plunger sticks", "assumption"),
        "size": Size((1, 3), (1, 3), "readings", "the dial shows its previous value for "
                     "this many readings (whole readings, rounded down)", "assumption"),
    },
    "sign": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a reading written with the wrong sign",
                     "assumption: a transcription slip"),
        "size": Size((1, 1), (1, 1), "readings", "one reading", "assumption"),
    },
    "skip": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a row skipped on the sheet",
                     "assumption: a transcription slip"),
        "size": Size((1, 1), (1, 1), "rows", "from that reading on, the stand's readings "
                     "are written one row late (each against the next posture) until it is "
                     "re-mounted", "assumption"),
    },
    "thermal-step": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a door opened", "assumption"),
        "size": Size((0.5, 2), (1, 4), "K", "a step in the room's temperature",
                     "assumption: a controlled room's door, a shop's gate", signed=True),
    },
    "lost-steps": {
        "rate": Size((0.5, 0.5), (1, 1), "1/h", "a drive loses steps", "assumption"),
        "size": Size((0.025, 0.1), (0.025, 0.1), "mm", "one joint's carriage is off by "
                     "this from that move on (the encoder reads the command)",
                     "assumption: 1-4 full steps of 25 um (a 5 mm lead, 200 steps a turn)",
                     signed=True),
    },
}
