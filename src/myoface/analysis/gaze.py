"""Where the eyes look: each eyeball's rotation read from the frame, on the model's own eyes.

The face model's eyeball (:mod:`myoface.face.eyes`) is a sphere of radius
:data:`~myoface.face.eyes.EYE_RADIUS_MM` behind each eye opening, fixed in the head; its iris
is the cap within :data:`IRIS_DEG` of its axis (the renderer draws the same eye,
:func:`myoface.render.dressing.eyeball`), so the limbus, the iris' edge, is a circle of radius
:data:`IRIS_RADIUS_MM` whose centre lies :data:`IRIS_DEPTH_MM` in front of the eyeball's
centre. Turning the eye by ``(yaw, pitch)`` (:func:`myoface.render.renderer.gaze_rotation`:
yaw towards the subject's left, pitch up, in the head frame) moves that circle on the sphere.

A frame's gaze (:class:`GazeEstimator`) is read photometrically, on the fit's terms: with the
head pose and the skin the 3-D fit found (:class:`~myoface.analysis.modelfit.ModelFit`), the
eyeball's centre is placed in the camera frame and the lid margins are projected into the
image (the fitted model's, or MediaPipe's points). Inside the opening, the pixels' brightness
is modelled as the eyeball seen there: a plane of brightness (the sclera and its shading),
a darker band along each lid margin (the lashes, the lid's shadow), and the iris, the
projection of the limbus for a candidate gaze (an ellipse, its edge softened by
:attr:`GazeSettings.edge_px`), with the pupil inside it (the model eye's: the edge of a cap of
:data:`~myoface.render.dressing.PUPIL_DEG` on the eyeball, its own brightness, darker than the
iris or not used). For each candidate the brightness coefficients are a linear
least-squares fit; the gaze is the candidate with the least residual (its iris darker than the
sclera), found on a grid from coarse to fine, both eyes together on the coarse grid (the eyes
turn together; each is then refined alone). No gaze is read where the lids are closed
(:attr:`GazeSettings.closed_ratio` of the person's open aperture, in the head frame: the
row says ``closed``), where the eye faces away from the camera or too little of it shows
(``hidden``), or where no iris is found (``not_found``).

A temporal filter (:class:`GazeSmoother`) averages each eye's last frames with weights that
fall with their distance from the newest reading: within a fixation the reading's noise is
averaged, a saccade (a jump of many times the noise between two frames) passes at once.

Why not MediaPipe's iris points (``refine_landmarks=True``, points 468-477): measured
2026-12-02 on renders of a personal face at known gaze with the true head pose and eyeball
centres, their centres give 4.4-8.0 deg RMS yaw and 6.7-10.7 deg pitch (a downward look of
-14.5 deg read as +4); the photometric reader here 0.6-1.4 and 2.1-2.4 deg on the same frames.
The refined face mesh also moves every one of the 468 points the fit consumes (median 1.6 px,
at most 6.3 px on single_face.mp4) and costs 8.5 ms a frame against 7.2 ms (tracking mode), so
it would have to run as a second graph beside the first: it is not run at all.

What limits the reading is where the eyeball's centre is: it comes from the fitted head pose
and the person's neutral, placed by MediaPipe's points, and a millimetre of error there is
5 degrees of gaze (the iris' centre is 10.5 mm from the eyeball's). The gaze is the eye's
rotation in the head, so each eye is read against its own socket in the frame
(:class:`EyeSocket`): the region around the eye (skin, lid margins, lashes, brow, and in the
opening the eyeball's sphere) is learnt in the head frame as the mean of the open frames'
patches, each sampled through the fit's pose (the iris left out: it moves with the gaze), and
each frame's patch is aligned to it: the shift found moves the eyeball's centre and the lids'
margins before the iris is read. The fit's misplacement changes from frame to frame about a
small mean, so the template sits at that mean and the alignment takes the rest away: on the
benchmark's recorded fit (2026-12-02) the eyeballs' centres 1.6-1.8 -> 0.7-1.2 px RMS in the
image (without the prior of :attr:`GazeSettings.socket_prior_mm`). Measured by oracle swaps
on the same frames (the reader without the socket, the worse eye's RMS): the fit's everything
8.7 deg; the eyeball's centre put at the truth's place in the image 6.1; and the lids' margins
the truth's too 3.7; and the head's true rotation (the head frame the gaze is given in) 2.3.
The socket takes the first step and part of the second (it moves the lids with the eye; their
own shape stays the fit's): 5.9 deg, 5.5 on a second clip. What is left is the lids' shape
(the fit's opening too open or too closed by 1-2.5 px, most at a blink's start, where the
truth counts the eye open to half closed) and the head's rotation error, which no local
offset removes. On the true geometry the reader alone is off by 2.7-2.9 deg RMS.

Measured again with the pupil in the model (2026-12-02, the benchmark's two clips, each
fit recorded once and replayed through the reader; the worse eye's RMS, clip 1 / clip 2):
the fit without the socket 6.90 / 7.41 deg; with it (the default) 4.64 / 5.17; the
eyeball's centre put each frame where the truth's is in the image (the fit's lids moved
with it, no socket) 3.78 / 3.21, its yaw 2.0-2.4; the reader on the true geometry 2.49 /
3.96. The yaw's error is mostly a bias: the socket's template sits at the fit's mean
misplacement, and that mean is not zero (the centres where the reader puts them 0.6 and 1.1
px to the image's right of the truth's, both clips alike: the yaw reads 2.8-4.3 deg to the
person's right; removing each eye's mean misplacement takes the yaw to 1.8-4.0 but not the
pitch, which the lids' shape and the head's pitch error, 2.0 deg RMS, hold). The pitch on
the true geometry is what the pupil helped (per eye 3.1-5.9 deg -> 2.7-5.2). On
single_face.mp4, where the person looks at the phone's screen throughout,
the reading holds within 0.7-1.0 deg yaw and 1.8 pitch (SD) and the blink's frames say
closed; its absolute direction (16 and 9.5 deg to the person's right, 5-8 up) cannot be
checked there (the screen's place beside the camera is not known). With the fit of
2026-12-02 11:20 UTC (replayed by ``tools/gaze_replay.py``): left (-21.3, +10.0) deg, SD
(1.2, 1.6), right (-14.0, +5.0), SD (1.5, 1.9), frames 26-28 (left) and 25-29 (right)
closed; the left eye turned 7.3 deg more to the person's right than the right one is what
eyes converging on a screen about half a metre away would do (63 mm apart: 7.2 deg), the
one check of the absolute reading there.

What it costs: the candidates' residuals are one compiled pass (:func:`_gaze_rss`: each
candidate's ellipses, whether it reaches the opening, and the sums over the pixels within its
iris' reach, run as vectors), and the opening's samples, the socket's patch and its alignment
are compiled too. Replayed on the benchmark's two recorded clips (2026-12-02, CPU time, the
median of 3 runs against the previous code in the same process): 6.0 -> 2.5 ms a frame, the
readings and states identical; ``myoface bench --only analysis.gaze_error_deg`` the same
4.643 deg, every reading of its detail the same. In the analysis benchmark's pass over
single_face.mp4 (the tracker's thread CPU in the reader, two runs each) 3.7-3.9 -> 1.4-1.5 ms
a frame, the pass 17.9-18.4 -> 15.3-16.2 ms; its gaze columns identical.

Where the eyeball's centre's bias comes from, and what did not remove it (2026-12-02,
``tools/gaze_replay.py`` on the benchmark's clip / a second clip, gaze seed 7 and camera
seed 3; the worse eye 4.64 / 5.17 deg as committed). The bias is the fit's lids: over the
frames open in the truth the fitted eye opening (its vertices' mean) sits 0.4-0.7 px to the
image's right of the truth's on every eye of both clips (and 0.4-0.5 px up on three of the
four), and the eyeball's centre, placed from the opening (10.4-10.5 mm behind its centroid in
the fit, 10.5-10.6 in the truth), goes with it; the socket follows the fit's misplacement
from frame to frame (its shift correlates 0.77-0.91 with the one needed) but its template
sits at the fit's mean, so the mean stays (0.6 / 1.0 px). An oracle of what a per-video
constant could give at best (each eye's centre moved by the shift the truth asks for,
head frame: left (-0.45, -0.3), right (-0.85, 0.3) mm on clip 1): 4.64 -> 4.16 deg (right
3.99 -> 2.50), and on clip 2 5.17 -> 5.11 (its left eye's pitch worse): the rest is frame to
frame. Tried and not kept: (1) the centre estimated per video from the iris, the reader's
residual summed over the frames as a function of a constant shift of the centre, the gaze
fitted again at each (the limbus' foreshortening is what tells the centre from the gaze):
the sum is sharp but its minimum is not the truth's (x right on the left eyes, -0.5 mm, but
+0.5 and -2.0 mm on the right ones where the truth asks about -0.85 and -0.3; y at the grid's edge,
+2 mm, where it asks -0.4 to +0.3): the model's iris against the image's is not unbiased to
a tenth of a millimetre. (2) The template's opening registered to the fitted neutral's lids
(the correlation of the template with the opening's soft mask): x 0.5-4 times the shift asked
for, y 0.5-1.1 mm low (the lashes and the lid's shadow darken the opening's top). (3) Refining the
coarse grid's two or three best basins and keeping the least residual: 4.63 / 5.24, and on
single_face.mp4 the left eye's pitch SD 1.6 -> 3.2 deg (the wrong basin fits better on those
frames). (4) The socket aligned a second time with the iris masked where it was read:
4.60 / 5.37. (5) The socket's prior (:attr:`GazeSettings.socket_prior_mm`) 2.5 mm: 4.26 /
5.78; none: 5.06 / 8.06. The left eye's pitch on clip 1 is held by frames after the second
blink (66-77), head turned 26 deg: the fit puts that eye 2.3 px too high, the socket takes
0.9 px of it, and the reading falls between two pitches 5.5 deg apart (0.5 and -5 deg
where the truth is 6.9; the reader on the true geometry -3.4 to +1.6 deg off there).
(6) The opening found in each frame by a two-region model of the pixels about it (inside
the lids' polygon the reader's eyeball: sclera plane, iris, pupil, bands; outside the skin's
plane and a lash band above the upper margin; the polygon shifted on a grid of 0.25 px): on
the right eye of clip 1 its per-frame shift does not follow the truth's (x: r = -0.19), its
median at the grid's edge, -2 px, where the truth asks -0.66: the bands and the lashes take
a shift of the margin as well as the margin does. What the fit's lids cost is in the
benchmark's detail (``eye_opening_px_mean``); the fix belongs to where the lids are fitted.

Where the 4.64 deg sits, broken down (2026-12-02, ``tools/gaze_replay.py``'s recordings of
the benchmark's clip, the second clip and the first undegraded, ``record bench-clean``; the
benchmark's detail has the new fields). Not the calibration: the fitted neutral's eyeball
centres are 0.01-0.08 mm (x) and 0.01-0.16 mm (y) from the truth's in the head frame
(``eyeball_centre_neutral_mm``). Each frame's pose puts them 0.5-1.0 px to the image's right
of the truth's on average (clip 1 left / right 0.44 / 1.09 px, ``eyeball_centre_px_mean``;
clip 2 0.74 / 0.71 on the frames whose lids rest), and every eye of both clips reads 2.6-4.3 deg to the person's
right. Undegraded, the worse eye 3.38 deg (left 2.81, its yaw bias -0.2; right 3.38, -3.4;
the reader on the true geometry 1.64 / 1.62): the camera's degradation costs 3.4 -> 4.6,
the rest is there without it. The pose's eye region follows the detector: MediaPipe's own
eye openings sit 0.1-0.9 px to the image's left of the truth on the degraded clips, the
fit's (after :class:`~myoface.analysis.landmarks.TrackerOffsets`) 0.4-0.7 px to its right;
on the person's model rendered sharp, full texture, frontal, MediaPipe reads both openings
1.2 px left, about what the offsets take off, more than its error on the benchmark's frames.
Its eye points move with what it is shown: the same frontal render with the texture at half
resolution (the benchmark's) reads the right opening at -0.18 px instead of -1.24, and a
gaze of +-15 deg moves either opening by up to 1 px. At 4-5 deg a pixel, 3 deg needs the
eye region within about 0.3 px: the fit's pose, not the reader.

What a registration of the eye's surroundings can give, measured (2026-12-02, issue 35;
``tools/gaze_replay.py replay`` on the two recorded clips, its ``placed`` numbers: over the
frames whose lids rest in the truth, each eye's centre and its skin ring, the canthi, the
lids' outer skin, the brow's lower edge and the cheek's upper, moved by the socket, against
the truth's in the image). The default socket leaves the skin ring 0.9-1.3 px RMS off (its
mean 0.4-0.7 px right), the eyeball's centre 1.3-1.7 px RMS (raw, before the socket,
1.6-2.3). Two parts, not one:

- the anchor: a template sampled through the fit's poses sits where those poses put the
  skin, on the first frame (``socket_template="first"``) as on their mean (the default).
  The first frame is not better placed than the mean (clip 1, frontal: the centres 0.4 /
  1.1 px right and 1.4 / 0.2 px up): anchored there, 5.34 / 4.75 deg. No template sampled
  through the fit's poses is anchored better than the fit; that needs a reference of where
  the eye is that is not the fit's (the recorded fits give none: the iris' foreshortening
  and the opening's edges were tried, above).
- the head's rotation: the eyeball's centre is 10-12 mm behind the skin ring, so a rotation
  error moves the two apart in the image; after the socket, the centre's error minus the
  skin's is 0.66-0.78 px RMS, correlated 0.96-0.99 with the fit's rotation error (2.0 deg
  RMS yaw, 1.9 pitch; 0.23-0.26 px a degree). No 2-D move of the eye region takes it off;
  a local rotation would have to be read from the patch's parallax (its depth spans about
  10 mm in front of a centre that lies 10 mm further back: by that estimate, not tried,
  the extrapolation about doubles the registration's noise, 0.2-0.3 mm on the true
  geometry).

The ceiling, by oracles (``oracle=skin``: each frame's offset the one that puts the skin
ring where the truth's is; ``oracle=centre``: the eyeball's centre there): 3.21 / 3.67 deg
and 3.49 / 3.21 (the reader on the true geometry 2.49 / 3.96), against 4.64 / 5.17: a
perfect registration of the eye's surroundings takes about 1.4 deg off and leaves the rest
to the reader and the head's rotation. Of that, the anchor is the larger part: the oracle's
offsets shifted by a constant so that their mean is the default socket's (its frame-to-frame
noise gone, its anchor kept; the skin oracle's mean offset is 0.3-0.5 mm left and 0.4-0.5 mm
down of the socket's on three of the four eyes) read 3.97 / 4.82 deg. The socket's own sensitivity, on renders of the
default face read through the true pose (tests/analysis/test_gaze.py): brows lowered move
the centre 0.14 / 0.36 px, brows raised 0.75 / 1.17 px and a squint 0.24 / 1.06 px (the
lids' skin moves with those two and the socket follows it); the aligned patch's NCC with
the template (0.62-0.83 there) does not tell them from the benchmark's head turns and
blinks (0.25-0.6 in the low tail), so it cannot gate the offset (the variants' numbers are
in :class:`GazeSettings`).

The reader's own pitch, on the true geometry: its error is per fixation and pushed away from
level (clip 2: a look at -1 deg read -7, one at 5 read 11; fitted on the truth's angles, a
gain of 1.24-1.28 in pitch on both clips, 1.03-1.09 in yaw; on clean frontal renders 1.07-1.09
and a look at 0 read 2-5.5 deg low). Where both lids cover the iris, the iris alone does not
place it: on a clean frontal render looking straight ahead its residual has one minimum, at
-6 deg; without the upper band the iris runs to the grid's edge (the person's lash line
along the upper margin is darker than the iris); with the band 1 px wide instead of 0.4 iris
radii, -6; with the iris' own brightness plane (the sclera's shading multiplies, the plane
adds), -6; with the iris faded towards the margins (a logistic of the distance, 1 px), -4;
with the pupil's term, 0. The pupil in every fine step (:attr:`GazeSettings.pupil`) fixes it
on the renders and flips on single_face.mp4 (above). Not kept either: taking the pupil's
reading only where its residual is lower, from the same start (single_face.mp4's left eye
pitch SD 3.95 deg); the pupil's contrast against the iris as a share of the iris' against
the sclera does not tell where the pupil can be trusted (median 0.27-0.34 on the renders,
0.17-0.22 on single_face.mp4, the quartiles overlapping); the temporal filter over 5-6
frames (4.64 -> 4.59-4.64).

Why a better head pose reads the gaze worse (2026-12-02, issue 35; ``tools/gaze_replay.py
record bench ... tracker=fit|photometric|flow``, the benchmark's clip, each fit recorded once,
its readings bit for bit the benchmark's). The photometric term's head rotation is off by
1.0 / 1.0 / 0.7 deg RMS against the landmark fit's 2.1 / 1.8 / 1.0, yet its worse eye read
6.67 deg against 5.05 (the anchored optical flow, ``--flow``, 5.82). What the gaze needs is
not the rotation but where the pose puts each eyeball's centre in the image, and that has two
parts: its spread from frame to frame and its mean. Over the frames whose lids rest, the
centres' error (px, x right and y down, left eye / right eye):

=============  ==========================  ==========================
fit            mean                        SD
=============  ==========================  ==========================
landmarks      (0.52, -0.40) (1.09, 0.06)  (1.45, 1.41) (0.95, 0.75)
photometric    (0.31, 0.75) (0.88, 1.14)   (0.81, 0.85) (0.75, 0.47)
flow           (0.44, 0.21) (1.05, 0.62)   (1.08, 1.25) (0.87, 0.62)
=============  ==========================  ==========================

The photometric term and the flow read each frame against the calibration frame's
appearance, so they halve the spread, but whatever the calibration frame's fit got wrong
about the eye stays, the same on every frame: the photometric fit puts both eyes 0.75 and
1.14 px low throughout (already on frame 0: 0.78 and 1.40), where the landmark fit's errors
scatter about a mean near zero in y. The socket (:class:`EyeSocket`) takes off the spread
(its template sits at the poses' mean) and cannot see a constant: the eye 1 px low reads
5.5 deg up on every frame (the benchmark's ``mean_deg``: +5.45 / +5.73 deg pitch), and with
its centre there the reader takes the iris' other pitch basin (the iris reaching under both
lids, above) on runs of frames, 11-23 deg up (the clip's frames 1-4, 14-18, 20 and 84-86), which
makes its pitch's SD 6 deg. The landmark fit's own mean, 0.4-1.1 px to the image's right on
every eye of every variant, is the yaw's bias (-2.6 to -4.8 deg, all three). An oracle of a
perfect per-video anchor (``oracle=anchor``: each eye moved by one constant, the mean of the
moves that put its centre where the truth's is; -0.3 to -0.9 mm in x, +0.6 / +0.9 mm in y
for the photometric fit) reads the worse eye at 3.60 (fit), 3.81 (photometric) and 3.91
(flow) deg against 4.61 / 6.66 / 5.33 with the same reader: the anchor is worth 1-3 deg,
most for the anchored fits, and what is left is frame to frame (the flow's left eye still
1.1 px RMS). No anchor of the eye better than the fit's is in the frames the reader sees:
MediaPipe's own points sit (-0.65, -0.96) and (-0.78, 0.20) px from the truth's about the
eyes (the skin ring, mean over the clip; the fit after the detector's offsets (0.41, -0.53)
and (0.77, -0.06)), and the eye's own features were tried above. It belongs where the
anchored fits take their reference: their calibration frame's eye region registered by the
landmarks of many frames rather than one would, by these numbers, take the photometric
fit's 0.75 / 1.14 px down to the landmark fit's -0.40 / 0.06 (not tried: the fit's module),
not the x both share. Tried since (2026-12-04, :data:`~myoface.analysis.modelfit.
REGISTER_APPEARANCE`, on with the photometric term): the appearance registered on up to 12
neutral frames' landmarks; the photometric fit's gaze on this clip 7.03 -> 3.36 deg (an oracle
registration 2.98), on four more clips 3.79, 3.66, 3.55, 7.68 -> 5.72, 5.55, 3.44, 4.50: the
lottery of one frame gone, MediaPipe's own bias at the eyes left.

Where the 4.28 deg sits, and what did not move it (2026-12-04, issue 35; recordings of
the benchmark's clip and the second clip, gaze seed 7 and camera seed 3, by
``tools/gaze_replay.py``; the worse eye, clip 1 / clip 2, 4.28 / 5.21 deg; on the renders
whose eye sockets were near-black, before :data:`~myoface.render.dressing.SOCKET` took the
conjunctiva's pink again: the benchmark's number since is in BENCHMARKS.md). The
right eye's yaw bias (-3.96 deg: its centre 0.92 px to the image's right) and both eyes'
pitch (4.1 deg RMS, its SD 3.9) hold it; the reader on the true geometry is 2.27 / 2.54 on
clip 1 and 3.50 / 3.65 on clip 2, so clip 2 fails on the reader alone. Measured, not kept:

- the pupil in every fine step (``pupil="all"``): on the true geometry 1.69 / 2.18 and 2.21 /
  2.45 deg (the reader's pitch 2.8 -> 1.9), end to end 4.49 and 4.81; on single_face.mp4 the
  pitch flips 4-6 deg down for single frames and back (frames 44-56), its median change from
  frame to frame 0.22 -> 0.67 deg: a real eye's pupil in a dark iris at 640x360 is not the
  model's (the catchlight inside it taken out by a top-hat mask: no better);
- the analysis' camera at the renders' true field of view (40 deg, not the assumed 45): the
  fit's head 51 mm nearer with the 45, and the same eye bias with the 40 (4.22 / 5.24);
- the offsets table (:class:`~myoface.analysis.landmarks.TrackerOffsets`) read on renders
  blurred like the frames, at the frames' texture resolution, or averaged over 6-12 renders
  jittered by +-0.5 px and +-4-5 deg per cell: 3.97-4.56 / 5.13-5.40, the moving head's pose
  1.73-1.84 deg against 1.82 (not monotonic in the renders averaged: noise);
- MediaPipe's attention mesh (``refine_landmarks``, :mod:`myoface.facemesh`): its eye
  openings are nearer the truth's, the fit's head pitch halves, and the gaze reads worse
  (4.78 / 6.21); the eye placed at its openings' centroid rather than the fit's: the yaw's
  bias gone without the socket (0.2-0.6 deg), the pitch's then +3-4 deg (its centroid sits
  0.6-0.8 px low of the model's), worse with the socket, which pulls the eye back to the
  fit's mean.

Where MediaPipe puts the eye openings on the renders, alone (15 views within +-20 deg yaw and
+-10 pitch, each degradation alone): 0.5-1.2 px left of the truth, changed by at most 0.6 px
by any degradation; the offsets table's cells for the same views vary by up to 2 px between
neighbours 10 deg apart (the detector's eye points jump with the view), and at the
benchmark's frames the table's prediction of MediaPipe's eye error correlates 0.66 (left) and
0.1-0.23 (right) with what MediaPipe does. The fit's openings (1.0-1.3 px RMS) are the best
of the fit's, MediaPipe's and MediaPipe's corrected by the table. What an anchor is worth on
the photometric fit, whose eyes stay put from frame to frame: a perfect per-video anchor of
each eye (``oracle=anchor``) with the pupil in every step reads 2.22 / 2.22 deg (without the
pupil 2.72 / 3.81); with the landmark fit the same oracle reads 4.1-4.6. So the reader and the
photometric fit's head would meet 3 deg, and the eye's place in the first frames would not:
it needs a detector of the eye's opening better than MediaPipe's 1 px.

A detector of the opening from the frame itself, measured 2026-12-06 (not built; the three
clips of the benchmark, the default analysis, median 6.56 deg): the model's lid loop slid over
the image to where a two-region model fits best (a plane of brightness, and a step across the
loop's soft edge, 0.5 px, over a band of 3 px either side). On the true geometry (the true
pose and skin) of clip (7, 3) it found the right eye's opening 1.6 px left of where it is
(SD 1.0 px a frame) and both 0.5 px low: the iris, the lashes and the corners' shading inside
the opening pull a region's edge. On the socket's template (:class:`EyeSocket`: the mean of the
open frames, the iris left out) of the three clips, the fitted poses' anchor error found with
0.4-1.0 mm of error (the right eye's 0.9-1.5 mm too far out, both 0.4-0.7 mm low): no better
than MediaPipe's. Nor is the placement the face's shape or the camera's: with the identity held
at zero (the person's exact neutral, which the benchmark's model is) or the analysis' camera at
the renders' field of view, the eyeballs' centres sit where they did (clip (7, 3), right eye:
1.44 and 1.89 px right of the truth against 1.54). It is the head pose, which the
photometric fit keeps from the calibration's registration: without the registration
(:data:`~myoface.analysis.modelfit.REGISTER_APPEARANCE` off) the clips read 3.40, 4.73 and
4.34 deg (median 4.34) with the head's rotation worse (clip (7, 3): mean pitch error 2.3
against 1.5 deg), the lottery of one frame's landmarks that the registration removed (its
docstring has the five clips).

The frame that calibrates sets that placement (2026-12-06, clip (7, 3), the benchmark's
analysis with the calibration frame forced, its neighbours and the appearance's registration
chosen over the whole clip's scores as for any calibration frame): as the benchmark calibrates
(frame 0, head frontal) 6.56 deg, the left and right eyeballs' centres (0.34, -1.02) and
(1.54, -1.04) px from the truth's on average; at frame 15 (yaw 30) 4.93 deg, (-0.64, -0.52)
and (-0.04, -0.51); at frame 45 (yaw -30) 8.30, (-0.30, -0.82) and (1.93, -0.94); at frame 60
(frontal, roll 11) 4.38, (-0.65, -0.90) and (0.47, 0.74). Each calibration leaves its own
steady offset of up to 2 px per eye, in a direction that changes with it, and the clip's
error runs from 4.4 to 8.3 deg with it: the neutral's pose and appearance are read from one
view, and what that view cannot tell stays in every frame. The expressions' readings show the
same (docs/expressions.md, "What holds the readings").

The offset is there at the calibration frame itself, and it is the pose's, not the
neutral's shape (2026-12-07, evening; the benchmark's three clips recorded by
``tools/gaze_replay.py``, all three calibrated on frame 0, head (0, 12.6, 13.6) deg). The
eye's skin ring (``tools/gaze_replay.py``'s ``placed``) is (2.43, -1.10) / (-0.03, -1.10) px
from the truth's on clip (0, 0), left / right eye, (1.11, -1.63) / (1.03, -2.30) on (7, 3),
(-0.96, -0.19) / (-1.52, -0.88) on (11, 5); the fitted skin's ring there is 0.03-0.62 mm
from the truth's in the head frame (0.04-1.05 px of the offset), the rest is where the
calibration's pose (and camera: the analysis assumes 45 deg, the renders have 40) puts it. The clips differ only in the camera's noise and the gaze (frame 0 looks at (6.8,
-6.9), (6.3, 11.9) and (-18.6, 0) deg): on the renderer's own frames of the face at rest,
MediaPipe's 16 contour points of an eye move 0.1-1.2 px (their mean) as the gaze alone
changes by 10-19 deg, at three head poses, and the rest of its face mesh 0.1-0.5 px, in no
direction that follows the gaze (a look 15 deg either way moved the left eye's points up by
1.05 and 1.16 px alike): the calibration's points are one draw of the detector's response to
what the eyes do, and no correction by the gaze read there would take it off. Nor is it the
assumed camera: with the analysis' camera at the renders' 40 deg the three clips read 3.99 /
6.76 / 5.36 deg (4.60 / 4.04 / 4.05 at 45), the skin rings (0.87, 0.04) / (0.00, -0.24),
(0.32, -0.66) / (1.55, -1.47), (-1.21, -0.79) / (-1.11, -1.47) px off on average: another
draw, no nearer the truth.

The eyes' vergence, measured and not constrained (2026-12-06, the benchmark's three clips and
(23, 9), (31, 1), the default analysis). Every clip reads the two eyes as diverging where the
truth's axes are parallel: the left eye's yaw less the right's errs by +2.7, +3.2, +5.0, +4.0
and +6.3 deg. With the yaws moved about their mean until the eyes no longer diverge (their
convergence held in [0, 18] deg), the worse eye reads 4.16, 6.56, 6.84, 7.55, 6.25 -> 3.54,
5.97, 5.73, 7.36, 5.50 deg (the benchmark's median 6.56 -> 5.73); what is left is both eyes'
common error (yaw -4.4 to +4.2 deg, pitch -2.6 to -8.6 deg, down on all five: on the
benchmark's three the eyeballs' centres placed 0.3-1.0 px high, above). Not taken: what the
reader measures is the iris' axis, and a person's visual axis lies nasal of it by angle kappa
(2.8-3.3 deg by synoptophore, 5.5-5.6 by Orbscan II: Basmak et al., J. Refract. Surg. 23,
2007), so real eyes fixating far away read as diverging by twice that; the renders' eyes
have none. A bound on the divergence that held on real eyes would be about -11 deg, where
none of these clips reaches.

Not the neutral's eye openings either (2026-12-06, night; the benchmark's three clips
recorded by ``tools/gaze_replay.py``, the worse eye, 4.24 / 3.55 / 4.39 deg as they are). On
clip (0, 0) the calibrated neutral has the eyes 0.6 mm further apart than the face's
(``eyeball_centre_neutral_mm``: +0.64 and -0.60 mm in x), on the other two within 0.33 mm. With
each eyeball's centre placed from the neutral's eye corners alone (their midpoint plus the
model's own offset from its corners' midpoint to its eyeball: MediaPipe's lid points, which
move with the gaze and the lids, left out): 4.38 / 3.46 / 5.28; the corners for x only, 4.39 /
3.43 / 5.21; for y only, 4.21 / 3.43 / 4.48. The yaw's bias of (0, 0)'s left eye (-4.7 deg)
stays with each: it is the frames' placement, not the neutral's.

What each eye's steady misplacement is worth, and MediaPipe over the whole clip as its anchor
(2026-12-07; the benchmark's three clips and four held out, (23, 9), (31, 1), (3, 1), (5, 2),
the default analysis recorded with each frame's points corrected by the detector's offsets).
Each eye's mean error taken off, the worse eye's RMS is 2.2-2.6 deg on the benchmark's three
(4.24 / 3.55 / 4.39 as they are); ``oracle=anchor`` 2.84 / 3.29 / 2.72; the reader on the true
geometry 2.38 / 3.43 / 2.96. MediaPipe's own eye openings, averaged over a clip's ~80 open
frames, sit where they sit on every clip alike (left (-0.18, -0.88), (0.07, -0.92), (0.15,
-1.01) px from the truth's; right (-1.10, 0.17), (-1.33, 0.20), (-1.13, 0.26)), where the fit's
placement wanders from clip to clip by up to 2 px: the detector's error is steady, the
calibration's draw is not. Less the offsets table's prediction (without the detector's
context, which is measured on the calibration's few frames and moved them by up to 1.1 px
from clip to clip), the clip's mean is within 0.5 px of the truth in x and 0.4-1.0 px high.
Each eye moved by the mean over the clip of that corrected opening less the fit's (its
centre, lids and socket, head frame): the seven clips' worse eye 4.24, 3.55, 4.39, 2.83, 5.47,
4.98, 3.70 -> 3.56, 3.46, 3.73, 3.48, 3.91, 3.56, 5.44 deg (median 4.24 -> 3.56; worse on two
clips, (23, 9) and (5, 2): the latter's left eye moved 1.9 mm); in x only, median 3.66; half
the move, 3.34; a running mean (what a causal reader could do, shrunk by 10 frames' worth
towards no move), 3.74, worse on three of the seven. Not taken: short of 3 deg either way,
needing the whole clip before the first reading, and resting on the offsets table's
correction of the eyes, which holds on renders of the person's own face and is not known on a
real one. The reference the gaze needs is still the eye's place to about 0.3 px, which
neither the detector's mean nor the calibration gives.

Nor a look into the camera (2026-12-07): an eye tracker's calibration, the person looking at a
known target, on the one target every video has. Built and measured, not kept: each eye's
offset the median over the look's frames of its reading less the direction from its eyeball's
centre (the fit's, through the frame's pose) to the camera's centre, each eye converging on
it, taken off every reading. Rendered with each eye its own gaze (the renderer's
``gaze={"l": ..., "r": ...}``), the benchmark's three clips after 45 frames looking into
the lens: with the head held still for the look, the readings there sit within 0.1-0.2 deg
of each other, but their offset is not the clip's (clip (7, 3): (-1.5, +1.1) deg on the look,
(+1.8, -1.2) over the clip), and the worse eye reads 2.59 / 3.28 / 4.07 deg as read and 2.58 /
4.08 / 3.41 calibrated (median 3.28 -> 3.41); with the head turning through the look (the
eyes then 20-37 deg into their orbits, counter-rotating as a fixating person's do), 3.86 /
4.56 / 5.58 -> 3.98 / 4.01 / 2.96. The misplacement is steady at a view, not over views:
what the fit gets wrong about the eye changes as the head turns, so one view's offset does
not carry to the others (an offset from the clip's own frames, which sample its views, reads
2.62 / 2.97 / 2.64: the simulation that made it look worth building).

How large the calibration's draw is (2026-12-07; the benchmark's clip (11, 5), the default
analysis recorded with the calibration frame forced, ``tools/gaze_replay.py``; the worse eye,
deg): calibrated on frame 0 (the default's choice) 4.39, on 5 3.24, 15 7.16, 33 3.50, 38 2.71,
44 4.08, 47 2.81, 55 2.76. The eyes' placement moves with it (frame 15: both eyes 1.4-2.0 px
to the image's left, the yaws +6.8 and +8.1 deg; frame 55: within 0.5 px, yaws +2.1 / -0.7), the
head's mean rotation error hardly (within 0.8 deg for every one), and neither the calibration
frame's gaze (-24 to +22 deg across these) nor MediaPipe's residual there (the eye points'
1.4-3.6 px RMS against the fitted model) predicts which draw is good. One clip's error spans
2.7-7.2 deg over the frames that could calibrate it. The other two clips alike
(``tools/gaze_replay.py record ... calibration=N``): clip (0, 0) on frames 0 (the default's
choice), 5, 40, 44, 47, 52, 55: 4.24, 2.86, 3.42, 3.53, 3.61, 3.06, 2.90; clip (7, 3) on 0,
5, 15, 35, 44, 47, 55: 3.55, 5.76, 6.13, 3.17, 5.12, 4.14, 3.48. The medians over the draws,
3.42 / 4.14 / 3.37 deg (the best 2.86 / 3.17 / 2.71): the benchmark's three clips are three
draws of a spread of about 1.5 deg either way, and a placement that did not rest on one frame
would take the spread away but not the error (about 3.4 deg); 3 deg needs the placement
itself better, not only steadier.

Two more stages asked (2026-12-07, afternoon; the three clips (0, 0) / (7, 3) / (11, 5) as
above, the default 4.24 / 3.55 / 4.39 deg): the person's neutral the model's own (the
calibration's identity offset zero, an oracle: the benchmark's face is the fitted model)
4.38 / 3.55 / 5.50, the eyes' placement in the frames still 0.5-1.1 px off (clip (0, 0):
the right eye's yaw -4.9 deg on average where the default's is -0.3): the neutral's eyeball
centres were not what held it; MediaPipe's points on the eyes' margins weighing 0 in the fit
(they move with the gaze, up to 1 px at 15 deg) 5.40 / 4.25 / 4.46; the appearance's albedo
the median over the registration frames rather than the calibration frame's alone (each
sampled at the pose its pixels give) 3.66 / 4.37 / 3.95. Each moves the clips by about the
draw's spread, in no one direction (docs/expressions.md, "Ten more stages asked").

What the camera costs the reader itself (2026-12-07, evening): clip (0, 0)'s frames rendered
again with one of the camera's parts at a time and read on the true geometry (the true pose,
skin and camera; left / right eye, RMS deg): none 0.82 / 1.24 (the pitch's gain, the
readings against the truth's, 1.01), the moving light 0.81 / 1.23, the background 0.82 /
1.24, the sensor's noise 0.82 / 1.16, H.264 0.84 / 1.32, the lens' 1-px blur 2.08 / 2.37
(pitch gain 1.17; 0.7 px 1.51 / 1.81, 1.5 px 3.05 / 3.29, gains 1.11 and 1.21): the blur
alone is what the reader loses to the camera, and it reads every look further from level
than it is. Not taken, on the blurred frames: the iris' edge softer in the model (0.9 px,
2.64 / 2.98), the frames sharpened first (unsharp masking, sigma 1 px, amount 1-2: 1.91 /
2.09-2.13), the margins' strips wider (lower 0.15 / 0.3: the clips' worse eye 4.28 / 4.82,
3.74 / 4.48, 4.38 / 4.77), the band wider (0.6: 2.03 / 2.35); the pupil in every fine step
reads them at 1.59 / 1.93 (``pupil``'s docstring has why it is not the default). The
model's own optimum moves with the blur (on a dense grid about the truth, the pitch 0.98 ->
2.17 deg RMS, gain 1.19 without the pupil): the skin beyond the lids' margins, blurred into
the opening, is what it does not model. Blurring every part of the model by the lens' 1 px
with the skin's plane outside the margins as three more columns takes that optimum to 1.48
deg (the iris' cover unblurred, the skin's columns alone, 1.77); read so in full (the skin's
columns, sigma 1 or 0.7 px), the three clips' worse eye 4.23 / 3.72 / 4.31 deg and 4.22 /
3.75 / 4.31 (the reader on the true geometry 2.09 / 2.87 / 2.19 from 2.10 / 3.37 / 2.96):
not a gain on the headline. Nor the whole model blurred (each candidate's iris and pupil
cut by the opening and convolved, a numpy reader at 150 ms a frame; sigma 1 / 0.7 / 1.2 px):
the reader on the true geometry 2.10 / 3.37 -> 1.85 / 2.59-2.67 (clips (0, 0) / (7, 3)), but
their worse eye 4.36 / -, 4.29 / 3.67, 4.43 / 3.67: read through the fit's geometry, the
blur-aware reader gains nothing either. What the
blur is worth in the headline: clip (0, 0)'s recorded fit (its poses and skin as the blurred
frames gave them) read on the same frames rendered without the blur (the camera's other
parts and draws the same): 4.24 -> 3.53 deg (pitch 2.46 -> 1.58, the yaw's bias -4.74 ->
-4.29); the whole analysis on those frames 4.14 (its placement moved the other way: the left
eye's centre 1.1 px left of the truth's, its yaw +4.24). On the clip rendered without any
camera part (``record bench-clean``) the analysis reads 1.97 deg. So of 4.24, about 0.7 is
the reader's under the lens' blur and the rest the eye's placement by the fit.

The blur's share is a gain, in yaw as well as pitch (2026-12-07, night; the three clips'
recordings replayed, each eye's readings regressed on the truth's over its open frames):
the slope is 1.03-1.12 in yaw and 1.12-1.22 in pitch on every eye of every clip, through the
fit's geometry and on the true one alike (their means 1.07 and 1.16), and the errors
correlate 0.16-0.81 with the true yaw and 0.35-0.45 with the true pitch. Divided by those
two gains, the readings' worse eye is 3.73 / 3.15 / 3.80 deg against 4.24 / 3.55 / 4.39
(clip (0, 0)'s left eye's yaw bias, -4.74 deg, stays). Not taken as a constant: the gain is
the lens' (1.01 without blur, 1.11 / 1.17 / 1.21 in pitch at 0.7 / 1 / 1.5 px), so a
correction must follow a blur measured on the video itself, an instrument not yet built or
validated; and it would leave the placement, which holds the rest.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numba
import numpy as np

from myoface.analysis.potentials import LUMA_601
from myoface.errors import MyofaceValueError
from myoface.face.eyes import EYE_RADIUS_MM, eye_loop, eyeball_center
from myoface.render.dressing import IRIS_DEG, PUPIL_DEG

#: the eyes, as (side, the face's landmark group of the opening's margin)
EYES = (("l", "eye_l"), ("r", "eye_r"))
#: the contractions CSV's gaze columns (degrees, head frame): yaw towards the subject's left,
#: pitch up, as :func:`myoface.render.renderer.gaze_rotation` turns the model's eyes
GAZE_COLUMNS = ("gaze_l_yaw_deg", "gaze_l_pitch_deg", "gaze_r_yaw_deg", "gaze_r_pitch_deg")
#: the CSV's per-eye state columns (:data:`GAZE_STATES`), beside :data:`GAZE_COLUMNS`
GAZE_STATE_COLUMNS = ("gaze_l_state", "gaze_r_state")
#: an eye's state: its gaze was read (``ok``), or why not: the lids are closed, the eye faces
#: away from the camera or too little of it shows, no iris was found in the opening
GAZE_STATES = ("ok", "closed", "hidden", "not_found")
#: the iris cap's half angle (degrees) on the model's eyeball: the renderer's
IRIS_DEG = float(IRIS_DEG)
#: the limbus' radius (mm): 5.82 mm on the model's eyeball, the adult's horizontal visible iris
#: diameter being 11.7 +- 0.5 mm (Khng & Osher, "Evaluation of the relationship between corneal
#: diameter and lens diameter", J. Cataract Refract. Surg. 34, 2008)
IRIS_RADIUS_MM = EYE_RADIUS_MM * float(np.sin(np.radians(IRIS_DEG)))
#: the limbus circle's centre in front of the eyeball's centre (mm)
IRIS_DEPTH_MM = EYE_RADIUS_MM * float(np.cos(np.radians(IRIS_DEG)))
#: the pupil's edge on the model's eyeball (the renderer's cap of :data:`PUPIL_DEG`): its
#: radius (mm) and its centre's depth in front of the eyeball's centre (mm)
PUPIL_RADIUS_MM = EYE_RADIUS_MM * float(np.sin(np.radians(PUPIL_DEG)))
PUPIL_DEPTH_MM = EYE_RADIUS_MM * float(np.cos(np.radians(PUPIL_DEG)))
#: the largest gaze angle read (degrees), each way: the renderer's range
#: (:data:`myoface.render.renderer.MAX_GAZE_RAD`)
MAX_GAZE_DEG = 45.0
#: BT.601 luma weights of (R, G, B): the brightness the reader models
LUMA = np.asarray(LUMA_601)


@dataclass(frozen=True)
class GazeSettings:
    """The reader's settings (measured 2026-12-02 on renders of the sample person's face at
    known gaze and pose, see :mod:`myoface.bench.gaze`).

    Attributes
    ----------
    coarse_deg, fine : the grid: steps of ``coarse_deg`` over +-:data:`MAX_GAZE_DEG` (on every
        other pixel: the iris spans 29 deg of the eyeball either way), then for each ``(step,
        half-width)`` of ``fine`` a grid around the best so far (every other pixel but for the
        last: on the renders the same readings to 0.01 deg, in 40 % less time; a first fine
        step of 1.5 deg over +-4.5 rather than 1 over +-5 read the benchmark's renders on the
        true geometry the same to 0.01 deg, 1.94 / 3.78 deg RMS yaw / pitch, in a fifth less
        time, 2026-12-02). The last step 0.5 deg over +-1 rather than 0.25 (the pupil's term
        makes its candidates dearer): on the two recorded clips 4.62 / 5.18 -> 4.64 / 5.17 deg,
        on the true geometry 2.48 / 3.97 -> 2.49 / 3.96, single_face.mp4's SDs the same; the
        reader with the pupil then costs what it did without it (6.5-6.7 ms CPU a frame,
        replayed, 2026-12-02).
    edge_px : the softness (px) of the iris' edge in the model: the renders' anti-aliasing and
        a webcam's blur are about a pixel wide (1.0 px read 2-6 deg worse on sharp renders).
        Measured and not taken (2026-12-06, ``tools/gaze_replay.py`` on the benchmark's three
        clips and two held out, the worse eye's deg, 0.6 / 0.45 / 0.35 / 0.25): sharper read
        the degraded renders better on every clip (4.21 -> 4.10 / 4.04 / 4.02, 3.65 -> 3.39 /
        3.42 / 3.31, 3.88 -> 3.87 / 3.86 / 3.79, 4.48 -> 4.42 / 4.41 / 4.47, 3.89 -> 3.64 /
        3.53 / 3.49; the reader on the true geometry 2.4-3.4 -> 2.0-2.8), but on
        single_face.mp4 the readings' SD stayed 0.7-1.6 deg at every value: the renderer's
        limbus is a hard line, a real one is not, and the benchmark's gain is the renderer's.
    upper_margin, lower_margin : pixels this close to the upper / lower lid margin, in iris
        radii, are not read (the lashes and the margin's own error; 0.1 and 0.05 against none:
        the worst reading 61 -> 3 deg yaw on one eye). The upper lid's 0.25: below its margin
        hang the lashes and the lid's shadow, and the fit puts the margin itself a little off
        (on the benchmark's clips 0.3 mm above the truth's, relative to the eyeball's centre,
        on every eye; its neutral 0.1-0.26 mm): a strip of lid read as eyeball pulls the
        iris down. Measured 2026-12-06 (``tools/gaze_replay.py``, each fit recorded once and
        replayed, 0.1 / 0.2 / 0.25 / 0.3 / 0.35; the worse eye's RMS deg): the benchmark's
        three clips 5.02 / 4.28 / 4.22 / 4.35 / 4.25, 5.89 / 4.49 / 3.65 / 3.54 / 3.49, 4.88 /
        3.99 / 3.89 / 4.05 / 4.16, two clips held out (gaze seeds 3 and 5, camera seeds 1 and
        2) 4.90 / 4.51 / 4.48 / 4.61 / 4.60, 5.02 / 4.30 / 3.89 / 3.99 / 3.97; the pitch's
        mean error -1.9 to -6.2 deg -> -0.3 to -3.1 at 0.25; the reader on the true geometry
        2.1-3.7 -> 2.1-3.4. With the lids' shape the truth's (the margins relative to the
        eyeball's centre) the pitch's bias went the same way at 0.1 (-2.0 -> -0.4 deg) and
        gained nothing more at 0.25. On single_face.mp4 the readings' SD 0.6-1.6 deg either
        way, their means within 1.1 deg, the blink's frames said closed alike.
    band : the width (iris radii) of the darker band the model allows along each margin.
    closed_ratio : the lids are closed below this share of the person's neutral aperture
        (the mean gap between the margins in the head frame, the fitted model's).
    closed_contrast, contrast_frames : the lids are also closed where the iris read is less
        dark against the sclera than ``closed_contrast`` of the eye's usual contrast (the
        90th percentile of its last ``contrast_frames`` readings: the open eye's are the
        strongest). MediaPipe does not close its lids on a blink: on single_face.mp4's blink
        (frames 26-28, the eyes shut) the fitted aperture fell only to 0.48-0.55 of the open
        one, but the contrast to 0.07-0.14 from 0.34-0.46.
    min_pixels : an opening with fewer pixels to read is ``hidden``.
    max_view_deg : an eyeball whose axis at rest is farther than this from the line to the
        camera is ``hidden`` (it faces away: the nose hides it).
    min_explained : the least share of the opening's brightness variance the iris must explain
        beyond the plane and bands, else ``not_found``.
    lids : whose lid margins bound the opening: ``"model"`` (the fitted model's, projected:
        on the renders 4.3-4.6 deg RMS against 6.8-7.0 with MediaPipe's points when the fit
        is good, fit-synthesis or photometric; alike, 9.1-9.4, with the default fit's) or
        ``"landmarks"`` (MediaPipe's points).
    prior : on the coarse grid, the weight of the squared distance (in units of
        :data:`MAX_GAZE_DEG`) from the last frame's gaze, against the residuals (each eye's
        relative to its own without an iris): it breaks near-ties between far apart minima
        (on single_face.mp4 one frame after the blink once read -20.5 deg pitch between
        readings of 8; on the benchmark 0.05 moved the error 8.77 -> 8.64 deg, 0.1 8.72).
    smooth_frames, smooth_deg : the temporal filter (:class:`GazeSmoother`): how many past
        frames, and the distance (deg) at which a past reading's weight falls to e^-1/2.
    socket : move each eye to where its socket is in the frame (:class:`EyeSocket`) before
        reading it (False: where the fit puts it). On the benchmark's recorded fit, replayed
        (2026-12-02), the worse eye 7.24 -> 4.98 deg (8.73 -> 5.94 with the fit before
        7308bb1) and on a second clip (another gaze programme and camera noise) 7.72 -> 5.51;
        on the true geometry 3.18 / 2.82 -> 2.87 / 2.77 and 4.10 / 4.66 -> 3.90 / 4.43 (left
        / right).
    socket_half_mm, socket_step_mm : the socket's region, +-(x, y) mm about the eyeball's
        centre (the opening is 29 mm wide, 12 tall on the sample person; the brows' lower
        edge and the cheek's upper are in), and its grid's step (0.66 px at 500 mm).
    socket_iris_px : the iris is left out of the socket's comparison this far (px) beyond its
        radius (its edge is blurred; where the coarse grid put it is a grid step off).
    socket_min_frames : a template pixel is used once this many frames have shown it.
    socket_max_mm, socket_iterations : the largest offset looked for, and the alignment's
        most steps.
    socket_open : only frames whose lids are at least this share of their open aperture apart
        (and whose iris is as dark against the sclera as that share of its usual contrast)
        teach the template or are aligned to it (a blink's lids cross the template's region:
        aligned, a frame at 0.35 of a blink read 35 deg off).
    socket_robust : the alignment's Huber weights (the residual beyond this many robust SDs
        counts linearly: the iris' remainder, a reflection; on the second clip 6.43 deg
        without, 5.52 with).
    socket_prior_mm : the prior SD (mm, each of x and y) of the fit's misplacement (measured
        1.2-1.8 px RMS at 500 mm: 0.9-1.4 mm), against the residuals' robust variance per 4
        grid points (about one independent sample of a blurred image). Along the lids' long
        edges a horizontal shift changes little: without the prior it ran away on the second
        clip, 7.72 -> 8.86 deg; with 1 mm the worse eye 6.61 / 5.83 (the two clips), with 2
        mm 5.60 / 5.95.
    socket_window_deg : after the move, the coarse grid again within this of its first best
        (a millimetre moves the gaze about 5 deg; the full grid read within 0.9 deg of it,
        better on one clip and worse on the other, for 4.6 times the candidates).
    socket_template, socket_opening, socket_learn_moved, socket_recentre, socket_agreement :
        variants of the socket measured and not kept (2026-12-02, ``tools/gaze_replay.py`` on
        the two recorded clips, the worse eye 4.64 / 5.17 deg as the default; the module's
        docstring has what they show). ``socket_template="first"`` anchors the template to the
        first frame learnt (the calibration frame on the benchmark), never updated: 5.34 / 4.75
        deg, that frame's own misplacement (0.4 / 1.1 px on clip 1) becoming the bias.
        ``socket_opening=False`` leaves the eye's opening (sclera, lid margins) out of the
        region: 4.76 / 6.15. ``socket_learn_moved`` learns each frame's patch where the socket
        found it (a sharper template, but one that follows its own offsets): 4.65 / 4.71, the
        right eyes' centres 0.2 px further off; with ``socket_recentre`` the mean of the learnt
        frames' offsets taken off each offset (the template kept at the fit's mean, as the
        default's, but sharp): 4.42 / 5.51 (clip 2's left eye 0.45 px further right).
        ``socket_agreement`` > 0: the pose's placement where the aligned patch's NCC with the
        template is below it (meant for expressions): 0.6 -> 4.72 / 5.52, 0.75 -> 5.11 / 5.85
        (the benchmark's head turns and blinks lower the NCC as much as a brow raise does).
    pupil : where the model has the pupil too (a darker disc inside the iris, its own
        coefficient, used only where it is darker than the iris and the iris than the
        sclera): ``"last"``, in the last fine step only (within 1 deg of the reading on the
        iris alone); ``"all"``, in every step but the first, full coarse grid; ``"none"``.
        The iris is taller than the opening: its top and bottom are under the lids, and its
        vertical place rests on the curvature of its sides; the pupil, whole inside the
        opening, pins it. Measured 2026-12-02 on the benchmark's two clips (replayed
        recorded fits; the worse eye, then the reader on the true geometry): none 4.98 / 5.51
        deg (true 2.87 / 4.42), last 4.66 / 5.20 (2.51 / 3.86), all 4.38 / 4.93 (2.26 /
        2.98). On single_face.mp4 (a dark brown iris, the upper lid's shadow across it, a
        reflection beside the pupil; the person holds their gaze) ``"all"`` then flipped
        between two readings 5-9 deg apart in pitch (SD 4.1 and 2.6 deg, against 1.7 without
        the pupil): the pupil's term takes either dark patch. ``"last"`` keeps it to the
        basin the iris found: SD 1.9 deg (yaw 0.7-1.0, as before), its pitch 1.2 deg lower.
        Measured again on 2da1fc6's tree (2026-12-02 14:40 UTC, with the tracker's edits then
        in progress; the fits recorded afresh by ``tools/gaze_replay.py``): the iris alone has two minima in pitch wherever it reaches
        under both lids (its top or its bottom edge set against a lid: on the true geometry
        of the second clip a look at -1 deg read -7, the residual at the truth 8 % above the
        minimum), the pupil's term one, at the truth. Last -> all: the reader on the true
        geometry 2.49 / 2.48 -> 1.79 / 2.29 deg (clip 1, left / right; pitch 3.1 / 2.7 ->
        2.0 / 2.2) and 3.41 / 3.96 -> 2.11 / 2.81 (clip 2; pitch 4.6 / 5.2 -> 2.5 / 3.3); on
        the recorded fits, the worse eye, 4.64 -> 4.54 and 5.17 -> 4.94 (the fit's eyeball
        centres' yaw bias, 2.6-4.3 deg on every eye, untouched). On single_face.mp4 replayed
        through ``gaze_replay``'s recording it held (pitch SD 1.67 / 1.95 -> 1.96 / 2.16 deg,
        single frames 4-5 deg low), but ``myoface analyze`` of the same video
        (tests/analysis/test_gaze.py's real-video test) flipped again: the right eye's pitch
        between about 8 and -1 deg, SD 3.7. It stays ``"last"``: the pupil's term needs a
        test of whether the image shows a pupil at all before it may move the basin. Tried
        with ``"all"`` and not kept either (the same replays): the band 0.6 (clip 2 4.94 ->
        5.25), the last step over +-1.5 deg (the same), the prior 0.1 (clip 1 4.38, clip 2's
        true geometry worse), the edge 0.8 px (worse everywhere).
    yoke_pitch : where both eyes are read, each is given their mean pitch. A person's eyes
        turn up and down together (Hering's law of equal innervation: vertical vergence is a
        degree or two at most, where the horizontal converges on a near target by 7 deg at
        half a metre, so the yaws are left alone); the two readings are then two
        measurements of one angle, each with its own error (its own lids, its own placement).
        Measured 2026-12-02 (``tools/gaze_replay.py`` recordings of the benchmark's clip,
        ``record bench ... tracker=fit|photometric|flow``, the worse eye, with
        ``reopen_frames``): fit 5.05 -> 4.61 deg (left 5.05 -> 4.06, right 4.40 -> 4.61: the
        right eye takes on some of the left's error), photometric 6.67 -> 6.66, flow 5.82 ->
        5.33; on renders of the default face at 15 known gazes, 3 head poses (the reader on
        the true geometry, tests/analysis/test_gaze.py) the pitch's RMS error 2.07 -> 0.94
        deg; on single_face.mp4 (``myoface analyze``) the left eye's pitch SD 2.59 -> 1.94 deg
        (the two eyes' means were 6.8 and 4.5 deg, now both 5.6). Where a person's eyes are
        not aligned (a vertical strabismus) it reports their mean for both.
    reopen_frames : the readings of an eye this many frames after its lids were said closed
        are withheld (``closed``): the lids reopen over frames, the fit's lids lag them (on
        the benchmark the fitted aperture stays at 0.86-0.96 of the open one on the frames a
        blink partly closes) and the iris half covered by the upper lid read 15-18 deg low
        on the frame after the second blink (truth closure 0.42). 1 against 0 on the
        recordings above: fit 4.76 -> 4.61 (with the yoke), flow 5.40 -> 5.33, photometric
        6.64 -> 6.66; 2 frames no better. (The frames a blink's closing half covers come
        before the closed one and are read: the reader is causal.)
    """

    coarse_deg: float = 6.0
    fine: tuple = ((1.5, 4.5), (0.5, 1.0))
    edge_px: float = 0.6
    upper_margin: float = 0.25
    lower_margin: float = 0.05
    band: float = 0.4
    closed_ratio: float = 0.3
    closed_contrast: float = 0.5
    contrast_frames: int = 60
    min_pixels: int = 12
    max_view_deg: float = 75.0
    min_explained: float = 0.05
    lids: str = "model"
    smooth_frames: int = 3
    smooth_deg: float = 2.0
    prior: float = 0.05
    socket: bool = True
    socket_half_mm: tuple = (20.0, 13.0)
    socket_step_mm: float = 0.5
    socket_iris_px: float = 1.5
    socket_min_frames: int = 3
    socket_max_mm: float = 4.0
    socket_iterations: int = 15
    socket_open: float = 0.8
    socket_robust: float = 2.0
    socket_prior_mm: float = 1.5
    socket_window_deg: float = 18.0
    socket_template: str = "mean"
    socket_opening: bool = True
    socket_learn_moved: bool = False
    socket_recentre: bool = False
    socket_agreement: float = 0.0
    pupil: str = "last"
    yoke_pitch: bool = True
    reopen_frames: int = 1

    def __post_init__(self):
        if self.pupil not in ("last", "all", "none"):
            raise MyofaceValueError(f"pupil must be 'last', 'all' or 'none'; got {self.pupil!r}")
        if self.socket_template not in ("mean", "first"):
            raise MyofaceValueError(
                f"socket_template must be 'mean' or 'first'; got {self.socket_template!r}"
            )
        if self.lids not in ("model", "landmarks"):
            raise MyofaceValueError(f"lids must be 'model' or 'landmarks'; got {self.lids!r}")
        if not (self.coarse_deg > 0 and self.edge_px > 0 and self.smooth_deg > 0):
            raise MyofaceValueError("coarse_deg, edge_px and smooth_deg must be > 0")
        if int(self.smooth_frames) < 0:
            raise MyofaceValueError(f"smooth_frames must be >= 0; got {self.smooth_frames}")
        if int(self.reopen_frames) < 0:
            raise MyofaceValueError(f"reopen_frames must be >= 0; got {self.reopen_frames}")


@dataclass(frozen=True)
class EyeGaze:
    """One eye's reading: ``yaw_deg`` (towards the subject's left) and ``pitch_deg`` (up) in the
    head frame, NaN unless ``state`` is ``"ok"``; ``explained``: the share of the opening's
    brightness variance the iris explains, and ``contrast`` its brightness less the sclera's
    (NaN when not read)."""

    yaw_deg: float = float("nan")
    pitch_deg: float = float("nan")
    state: str = "not_found"
    explained: float = float("nan")
    #: the iris' brightness less the sclera's (luma, < 0), NaN when not read
    contrast: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.state == "ok"

    @property
    def angles_rad(self) -> tuple[float, float]:
        return float(np.radians(self.yaw_deg)), float(np.radians(self.pitch_deg))


@dataclass(frozen=True)
class Gaze:
    """Both eyes' readings of a frame (:class:`EyeGaze`), the subject's ``left`` and ``right``."""

    left: EyeGaze = field(default_factory=EyeGaze)
    right: EyeGaze = field(default_factory=EyeGaze)
    #: where the reader put each eye on this frame, ``{side: (offset, opening)}``: its
    #: socket's offset (mm, head frame x and y; None: none found) and the fit's opening before
    #: it (px; None: not placed), as :attr:`GazeEstimator.offsets` and ``openings`` had them
    #: right after the frame was read (:meth:`GazeEstimator.measure`; the benchmark's detail)
    placed: dict | None = field(default=None, compare=False, repr=False)

    def eye(self, side: str) -> EyeGaze:
        return self.left if side == "l" else self.right

    def cells(self) -> list[str]:
        """The values of :data:`GAZE_COLUMNS` then :data:`GAZE_STATE_COLUMNS` as CSV cells
        (empty angles where an eye was not read)."""
        out = []
        for e in (self.left, self.right):
            out += ["" if not e.ok else f"{v:.2f}" for v in (e.yaw_deg, e.pitch_deg)]
        return [*out, self.left.state, self.right.state]

    def common_rad(self) -> tuple[float, float] | None:
        """The eyes' common gaze ``(yaw, pitch)`` rad for the renderer (which turns both eyes
        alike): the mean of the eyes read, None when neither was."""
        read = [e for e in (self.left, self.right) if e.ok]
        if not read:
            return None
        return tuple(float(np.radians(np.mean([getattr(e, a) for e in read]))) for a in
                     ("yaw_deg", "pitch_deg"))  # fmt: skip


# ------------------------------------------------------------------ geometry


def gaze_directions(yaw_deg, pitch_deg) -> np.ndarray:
    """Unit vectors (..., 3), head frame, of gazes ``(yaw, pitch)`` degrees: straight ahead
    (+z) turned as :func:`myoface.render.renderer.gaze_rotation` turns the eyeball."""
    y = np.radians(np.asarray(yaw_deg, dtype=np.float64))
    p = np.radians(np.asarray(pitch_deg, dtype=np.float64))
    return np.stack([np.sin(y) * np.cos(p), np.sin(p), np.cos(y) * np.cos(p)], axis=-1)


def gaze_angles(directions) -> np.ndarray:
    """``(yaw, pitch)`` degrees (..., 2) of unit vectors (..., 3), head frame: the inverse of
    :func:`gaze_directions`."""
    d = np.asarray(directions, dtype=np.float64)
    yaw = np.degrees(np.arctan2(d[..., 0], d[..., 2]))
    pitch = np.degrees(np.arcsin(np.clip(d[..., 1], -1.0, 1.0)))
    return np.stack([yaw, pitch], axis=-1)


def iris_ellipses(camera, centre_mm, directions, depth_mm: float = IRIS_DEPTH_MM,
                  radius_mm: float = IRIS_RADIUS_MM) -> tuple[np.ndarray, ...]:  # fmt: skip
    """The limbus' image (an ellipse, pixels) for each gaze ``directions`` (K, 3), camera
    frame, of an eyeball centred at ``centre_mm`` (3,), camera frame (or of another circle
    about the eye's axis: ``radius_mm`` across, ``depth_mm`` in front of the centre, as the
    pupil's edge).

    Returns ``(centres (K, 2) px, tilt (K, 2) unit image direction of the axis' tilt,
    major (K,) px, minor (K,) px, facing (K,) bool)``: the circle seen at its centre's depth
    (weak perspective over the eye: its 12 mm against the head's 300+ mm), its minor axis
    along the image of the gaze direction, shortened by the cosine between the gaze and the
    line to the camera; ``facing`` where that cosine exceeds 0.05 (the iris faces the camera).
    """
    g = np.asarray(directions, dtype=np.float64)
    d = np.asarray(centre_mm, dtype=np.float64)[None, :] + depth_mm * g
    c2 = camera.project(d)
    tip = camera.project(d + 0.5 * g)
    t = tip - c2
    n = np.linalg.norm(t, axis=1, keepdims=True)
    t = np.where(n > 1e-9, t / np.maximum(n, 1e-12), np.array([[1.0, 0.0]]))
    view = -d / np.linalg.norm(d, axis=1, keepdims=True)
    cos = (g * view).sum(axis=1)
    scale = camera.focal_px / np.maximum(-d[:, 2], 1e-6)
    major = radius_mm * scale
    minor = major * np.maximum(np.abs(cos), 0.05)
    return c2, t, major, minor, cos > 0.05


def iris_cover(px, centres, tilt, major, minor, edge_px) -> np.ndarray:
    """How much of each pixel (N,) the iris of each candidate (K,) covers, (K, N) in [0, 1]: a
    logistic of the signed distance (px, along the ray from the ellipse's centre) to its edge,
    of scale ``edge_px``. The reference of :func:`_candidates_rss`'s kernel."""
    d = px[None, :, :] - centres[:, None, :]
    ut = (d * tilt[:, None, :]).sum(-1)
    normal = np.stack([-tilt[:, 1], tilt[:, 0]], axis=-1)
    un = (d * normal[:, None, :]).sum(-1)
    rho = np.sqrt((ut / minor[:, None]) ** 2 + (un / major[:, None]) ** 2)
    r = np.sqrt(ut**2 + un**2)
    dist = np.where(rho > 1e-9, r * (1.0 - rho) / np.maximum(rho, 1e-9), major[:, None])
    z = np.clip(dist / edge_px, -50.0, 50.0)
    return np.where(z < -12.0, 0.0, 1.0 / (1.0 + np.exp(-z)))  # (< 1e-5: none, as the kernel)


def _rss_numpy(px, bright, fixed, proj, centres, tilt, major, minor, edge_px, pupil=None):
    """Per candidate: the residual sum of squares of ``bright`` (N,) fitted by the ``fixed``
    columns (N, m) and the candidate's iris cover (and, with ``pupil`` = its ellipses'
    ``(centres (K, 2), major (K,), minor (K,))``, the pupil's cover: darker than the iris or
    not there, its coefficient <= 0), and the iris column's coefficient (plain numpy;
    :func:`_rss_numba` is the same)."""
    cover = iris_cover(px, centres, tilt, major, minor, edge_px)
    gti = fixed.T @ bright
    base = bright @ bright - gti @ proj @ gti
    u = cover @ fixed  # (K, m)
    s = (cover * cover).sum(1) - np.einsum("km,mn,kn->k", u, proj, u)
    r = cover @ bright - u @ (proj @ gti)
    s = np.maximum(s, 1e-12)
    rss, coef = base - r * r / s, r / s
    if pupil is None:
        return rss, coef
    pc = iris_cover(px, pupil[0], tilt, pupil[1], pupil[2], edge_px)
    v = pc @ fixed
    s22 = (pc * pc).sum(1) - np.einsum("km,mn,kn->k", v, proj, v)
    s12 = (cover * pc).sum(1) - np.einsum("km,mn,kn->k", u, proj, v)
    r2 = pc @ bright - v @ (proj @ gti)
    det = s * s22 - s12 * s12
    good = det > 1e-12 * s * np.maximum(s22, 1e-12)
    det = np.where(good, det, 1.0)
    a1 = (s22 * r - s12 * r2) / det
    a2 = (s * r2 - s12 * r) / det
    both = good & (a2 < 0) & (a1 < 0)
    return (np.where(both, base - (a1 * r + a2 * r2), rss), np.where(both, a1, coef))


#: the compiled sums' floating-point licence: reassociation (the sums over the pixels run as
#: vectors) and fused multiply-adds; no assumption about NaN or infinity
_FAST = {"reassoc", "contract", "nsz", "arcp"}


@numba.njit(cache=True, nogil=True, fastmath=_FAST, error_model="numpy", inline="always")
def _logistic(z):  # pragma: no cover
    """The cover ``1 / (1 + exp(-z))`` of :func:`iris_cover` (1 above ``z`` = 30, 0 below -12),
    with ``exp`` as a polynomial the compiler can run on vectors: ``exp(t / 64) ** 64``, the
    Taylor series of degree 14 (its error below 1e-17 for ``|t / 64|`` <= 0.47), squared six
    times (relative error ~1e-14 against numpy's)."""
    t = min(max(-z, -30.0), 12.0) * (1.0 / 64.0)
    e = 1.0 / 87178291200.0
    e = e * t + 1.0 / 6227020800.0
    e = e * t + 1.0 / 479001600.0
    e = e * t + 1.0 / 39916800.0
    e = e * t + 1.0 / 3628800.0
    e = e * t + 1.0 / 362880.0
    e = e * t + 1.0 / 40320.0
    e = e * t + 1.0 / 5040.0
    e = e * t + 1.0 / 720.0
    e = e * t + 1.0 / 120.0
    e = e * t + 1.0 / 24.0
    e = e * t + 1.0 / 6.0
    e = e * t + 0.5
    e = e * t + 1.0
    e = e * t + 1.0
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    e = e * e
    c = 1.0 / (1.0 + e)
    c = 1.0 if z > 30.0 else c
    return 0.0 if z < -12.0 else c


@numba.njit(cache=True, nogil=True, fastmath=_FAST, error_model="numpy", inline="always")
def _cover_z(x, y, cx, cy, tx, ty, ia, ib, major, edge_px):  # pragma: no cover
    """The logistic's argument of :func:`iris_cover` at the pixel ``(x, y)`` for the ellipse
    centred at ``(cx, cy)``, tilted ``(tx, ty)``, of inverse radii ``ia`` (major), ``ib``."""
    dx = x - cx
    dy = y - cy
    ut = dx * tx + dy * ty
    un = -dx * ty + dy * tx
    rho = np.sqrt((ut * ib) * (ut * ib) + (un * ia) * (un * ia))
    z = np.sqrt(ut * ut + un * un) * (1.0 - rho) / (max(rho, 1e-9) * edge_px)
    return z if rho > 1e-9 else major / edge_px


@numba.njit(cache=True, nogil=True, fastmath=_FAST, error_model="numpy", inline="always")
def _cover(x, y, cx, cy, tx, ty, ia, ib, major, edge_px):  # pragma: no cover
    """How much of the pixel ``(x, y)`` the ellipse covers (:func:`iris_cover`, one pixel):
    :func:`_logistic` of :func:`_cover_z`; 0 beyond 12 edge widths outside. Every compiled
    kernel's cover, the iris' and the pupil's."""
    return _logistic(_cover_z(x, y, cx, cy, tx, ty, ia, ib, major, edge_px))


@numba.njit(cache=True, nogil=True)
def _rss_numba(px, bright, fixed, proj, centres, tilt, major, minor, edge_px,
               pupil_centres, pupil_major, pupil_minor):  # pragma: no cover  # fmt: skip
    """:func:`_rss_numpy`, compiled; no pupil when ``pupil_centres`` has no rows."""
    n, m = fixed.shape
    k_all = centres.shape[0]
    with_pupil = pupil_centres.shape[0] == k_all
    gti = np.zeros(m)
    for i in range(n):
        for j in range(m):
            gti[j] += fixed[i, j] * bright[i]
    pg = np.zeros(m)
    for j in range(m):
        for q in range(m):
            pg[j] += proj[j, q] * gti[q]
    base = bright @ bright
    for j in range(m):
        base -= gti[j] * pg[j]
    rss = np.empty(k_all)
    coef = np.empty(k_all)
    u = np.zeros(m)
    v = np.zeros(m)
    for k in range(k_all):
        cx, cy = centres[k, 0], centres[k, 1]
        tx, ty = tilt[k, 0], tilt[k, 1]
        ia, ib_ = 1.0 / major[k], 1.0 / minor[k]
        if with_pupil:
            qx, qy = pupil_centres[k, 0], pupil_centres[k, 1]
            pa, pb_ = 1.0 / pupil_major[k], 1.0 / pupil_minor[k]
        for j in range(m):
            u[j] = 0.0
            v[j] = 0.0
        ii = 0.0
        ib = 0.0
        pp = 0.0
        ip = 0.0
        pbr = 0.0
        for i in range(n):
            c = _cover(px[i, 0], px[i, 1], cx, cy, tx, ty, ia, ib_, major[k], edge_px)
            if c == 0.0:  # (outside: covers < 1e-5, taken as nothing; the pupil is inside)
                continue
            ii += c * c
            ib += c * bright[i]
            for j in range(m):
                u[j] += c * fixed[i, j]
            if with_pupil:
                c2 = _cover(px[i, 0], px[i, 1], qx, qy, tx, ty, pa, pb_, pupil_major[k], edge_px)
                if c2 == 0.0:
                    continue
                pp += c2 * c2
                ip += c * c2
                pbr += c2 * bright[i]
                for j in range(m):
                    v[j] += c2 * fixed[i, j]
        upu = 0.0
        upg = 0.0
        for j in range(m):
            upg += u[j] * pg[j]
            for q in range(m):
                upu += u[j] * proj[j, q] * u[q]
        s = max(ii - upu, 1e-12)
        r = ib - upg
        rss[k] = base - r * r / s
        coef[k] = r / s
        if with_pupil:
            vpv = 0.0
            upv = 0.0
            vpg = 0.0
            for j in range(m):
                vpg += v[j] * pg[j]
                for q in range(m):
                    vpv += v[j] * proj[j, q] * v[q]
                    upv += u[j] * proj[j, q] * v[q]
            s22 = pp - vpv
            s12 = ip - upv
            r2 = pbr - vpg
            det = s * s22 - s12 * s12
            if det > 1e-12 * s * max(s22, 1e-12):
                a1 = (s22 * r - s12 * r2) / det
                a2 = (s * r2 - s12 * r) / det
                if a2 < 0.0 and a1 < 0.0:  # (the pupil darker than the iris, the iris
                    # than the sclera; else no pupil: as above)
                    rss[k] = base - (a1 * r + a2 * r2)
                    coef[k] = a1
    return rss, coef


def _candidates_rss(px, bright, fixed, proj, centres, tilt, major, minor, edge_px,
                    pupil=None):  # fmt: skip
    """:func:`_rss_numpy`, compiled (:func:`_rss_numba`)."""
    if pupil is None:
        pupil = (np.zeros((0, 2)), np.zeros(0), np.zeros(0))
    return _rss_numba(px, bright, fixed, proj, centres, tilt, major, minor, edge_px, *pupil)


@numba.njit(cache=True, nogil=True)
def _ellipse_of(ex, ey, ez, gx, gy, gz, depth, radius, f, cx, cy):  # pragma: no cover
    """:func:`iris_ellipses` for one gaze ``(gx, gy, gz)`` (camera frame) of the eyeball
    centred at ``(ex, ey, ez)``: centre (x, y), tilt (x, y), major, minor, cos."""
    dx, dy, dz = ex + depth * gx, ey + depth * gy, ez + depth * gz
    den = max(-dz, 1e-6)
    x, y = cx + f * dx / den, cy - f * dy / den
    tz = dz + 0.5 * gz
    tden = max(-tz, 1e-6)
    tx = cx + f * (dx + 0.5 * gx) / tden - x
    ty = cy - f * (dy + 0.5 * gy) / tden - y
    n = np.sqrt(tx * tx + ty * ty)
    if n > 1e-9:
        tx, ty = tx / max(n, 1e-12), ty / max(n, 1e-12)
    else:
        tx, ty = 1.0, 0.0
    dn = np.sqrt(dx * dx + dy * dy + dz * dz)
    cos = (gx * -dx + gy * -dy + gz * -dz) / dn
    major = radius * (f / den)
    minor = major * max(abs(cos), 0.05)
    return x, y, tx, ty, major, minor, cos


@numba.njit(cache=True, nogil=True, fastmath=_FAST, error_model="numpy")
def _iris_sums(xs, ys, bright, f0, f1, f2, f3, f4, i0, i1, cx, cy, tx, ty, ia, ib, major,
               edge_px, out):  # pragma: no cover  # fmt: skip
    """Over the pixels ``i0..i1``: the iris cover's sums of :func:`_rss_numba` (its square,
    its product with the brightness and with each fixed column ``f0..f4``) into ``out[:7]``."""
    ii = cb = u0 = u1 = u2 = u3 = u4 = 0.0
    for i in range(i0, i1):
        c = _cover(xs[i], ys[i], cx, cy, tx, ty, ia, ib, major, edge_px)
        ii += c * c
        cb += c * bright[i]
        u0 += c * f0[i]
        u1 += c * f1[i]
        u2 += c * f2[i]
        u3 += c * f3[i]
        u4 += c * f4[i]
    out[0], out[1], out[2], out[3], out[4], out[5], out[6] = ii, cb, u0, u1, u2, u3, u4


@numba.njit(cache=True, nogil=True, fastmath=_FAST, error_model="numpy")
def _pupil_sums(xs, ys, bright, f0, f1, f2, f3, f4, i0, i1, cx, cy, tx, ty, ia, ib, major,
                qx, qy, pa, pb, pmajor, edge_px, out):  # pragma: no cover  # fmt: skip
    """:func:`_iris_sums` and the pupil's (centred at ``(qx, qy)``, the iris' tilt, inverse
    radii ``pa``, ``pb``; none where the iris has none) into ``out[7:]``: its square, its
    product with the iris' cover, the brightness and each fixed column."""
    ii = cb = u0 = u1 = u2 = u3 = u4 = 0.0
    pp = ip = pbr = v0 = v1 = v2 = v3 = v4 = 0.0
    for i in range(i0, i1):
        x, y, b = xs[i], ys[i], bright[i]
        c = _cover(x, y, cx, cy, tx, ty, ia, ib, major, edge_px)
        ii += c * c
        cb += c * b
        u0 += c * f0[i]
        u1 += c * f1[i]
        u2 += c * f2[i]
        u3 += c * f3[i]
        u4 += c * f4[i]
        c2 = _cover(x, y, qx, qy, tx, ty, pa, pb, pmajor, edge_px)
        c2 = c2 if c > 0.0 else 0.0
        pp += c2 * c2
        ip += c * c2
        pbr += c2 * b
        v0 += c2 * f0[i]
        v1 += c2 * f1[i]
        v2 += c2 * f2[i]
        v3 += c2 * f3[i]
        v4 += c2 * f4[i]
    out[0], out[1], out[2], out[3], out[4], out[5], out[6] = ii, cb, u0, u1, u2, u3, u4
    out[7], out[8], out[9] = pp, ip, pbr
    out[10], out[11], out[12], out[13], out[14] = v0, v1, v2, v3, v4


@numba.njit(cache=True, nogil=True)
def _gaze_rss(xs, ys, bright, fx, proj, centre, rot, f, cx, cy, yaw, pitch, edge_px,
              pupil):  # pragma: no cover  # fmt: skip
    """:meth:`_Eye.rss` in one pass: for each candidate gaze ``(yaw, pitch)`` (K,) degrees,
    head frame, turned into the camera frame by ``rot``, its iris' (and with ``pupil`` its
    pupil's) ellipse (:func:`iris_ellipses`) about the eyeball's centre ``centre`` (3,) mm
    through the camera (``f``, ``cx``, ``cy``), whether it is used (facing the camera, its
    centre within its major radius of the pixels' box) and, where it is, the residual and the
    iris' coefficient of :func:`_rss_numba` on the pixels at ``xs``, ``ys`` (N,) (sorted by
    ``xs``; brightness ``bright``, the plane and bands ``fx`` (5, N), ``proj`` the inverse of
    their normal matrix). Only the pixels within the major radius plus 12 edge widths (plus a
    pixel) of the ellipse's centre in x are summed: beyond, a pixel is outside the ellipse by
    more than the 12 widths beyond which :func:`_rss_numba` counts no cover (the sums are the
    same, but for the order of the additions and the logistic's polynomial, ~1e-12).
    Returns ``(rss (K,) inf where not used or the iris is not darker, coef (K,), base)``."""
    n = xs.shape[0]
    k_all = yaw.shape[0]
    gti = np.zeros(5)
    for i in range(n):
        for j in range(5):
            gti[j] += fx[j, i] * bright[i]
    pg = np.zeros(5)
    for j in range(5):
        for q in range(5):
            pg[j] += proj[j, q] * gti[q]
    base = bright @ bright
    for j in range(5):
        base -= gti[j] * pg[j]
    lox, loy, hix, hiy = np.inf, np.inf, -np.inf, -np.inf
    for i in range(n):
        lox, hix = min(lox, xs[i]), max(hix, xs[i])
        loy, hiy = min(loy, ys[i]), max(hiy, ys[i])
    rss = np.full(k_all, np.inf)
    coef = np.zeros(k_all)
    out = np.zeros(15)
    ex, ey, ez = centre[0], centre[1], centre[2]
    for k in range(k_all):
        y = np.radians(yaw[k])
        p = np.radians(pitch[k])
        hx, hy, hz = np.sin(y) * np.cos(p), np.sin(p), np.cos(y) * np.cos(p)
        gx = hx * rot[0, 0] + hy * rot[0, 1] + hz * rot[0, 2]
        gy = hx * rot[1, 0] + hy * rot[1, 1] + hz * rot[1, 2]
        gz = hx * rot[2, 0] + hy * rot[2, 1] + hz * rot[2, 2]
        cx_, cy_, tx, ty, major, minor, cos = _ellipse_of(
            ex, ey, ez, gx, gy, gz, IRIS_DEPTH_MM, IRIS_RADIUS_MM, f, cx, cy
        )
        if not (cos > 0.05 and lox - major < cx_ < hix + major
                and loy - major < cy_ < hiy + major):  # fmt: skip
            continue
        reach = major + 12.0 * edge_px + 1.0
        i0 = np.searchsorted(xs, cx_ - reach)
        i1 = np.searchsorted(xs, cx_ + reach)
        if pupil:
            qx, qy, _, _, pmaj, pmin, _ = _ellipse_of(
                ex, ey, ez, gx, gy, gz, PUPIL_DEPTH_MM, PUPIL_RADIUS_MM, f, cx, cy
            )
            _pupil_sums(xs, ys, bright, fx[0], fx[1], fx[2], fx[3], fx[4], i0, i1, cx_, cy_,
                        tx, ty, 1.0 / major, 1.0 / minor, major, qx, qy, 1.0 / pmaj,
                        1.0 / pmin, pmaj, edge_px, out)  # fmt: skip
        else:
            _iris_sums(xs, ys, bright, fx[0], fx[1], fx[2], fx[3], fx[4], i0, i1, cx_, cy_,
                       tx, ty, 1.0 / major, 1.0 / minor, major, edge_px, out)  # fmt: skip
        upu = 0.0
        upg = 0.0
        for j in range(5):
            upg += out[2 + j] * pg[j]
            for q in range(5):
                upu += out[2 + j] * proj[j, q] * out[2 + q]
        s = max(out[0] - upu, 1e-12)
        r = out[1] - upg
        rss[k] = base - r * r / s
        coef[k] = r / s
        if pupil:
            vpv = 0.0
            upv = 0.0
            vpg = 0.0
            for j in range(5):
                vpg += out[10 + j] * pg[j]
                for q in range(5):
                    vpv += out[10 + j] * proj[j, q] * out[10 + q]
                    upv += out[2 + j] * proj[j, q] * out[10 + q]
            s22 = out[7] - vpv
            s12 = out[8] - upv
            r2 = out[9] - vpg
            det = s * s22 - s12 * s12
            if det > 1e-12 * s * max(s22, 1e-12):
                a1 = (s22 * r - s12 * r2) / det
                a2 = (s * r2 - s12 * r) / det
                if a2 < 0.0 and a1 < 0.0:  # (as :func:`_rss_numba`)
                    rss[k] = base - (a1 * r + a2 * r2)
                    coef[k] = a1
        if not coef[k] < 0.0:
            rss[k] = np.inf
    return rss, coef, base


# ------------------------------------------------------------------ the opening's pixels


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _opening_pixels(x0, y0, x1, y1, poly, upper, lower):  # pragma: no cover
    """The pixels (col, row) of the box ``x0..x1, y0..y1`` whose centres (col + 0.5, row +
    0.5) lie inside the closed polygon ``poly`` (M, 2) (even-odd rule), as (N, 2) centres,
    with each one's distance (N,) to the polylines ``upper`` and ``lower``: what
    :func:`_inside_polygon` and :func:`_chain_distance` give, in one pass (they took 6 ms of
    the reader's 20 a frame, in numpy's temporaries)."""
    nmax = (x1 - x0 + 1) * (y1 - y0 + 1)
    px = np.empty((nmax, 2))
    du = np.empty(nmax)
    dl = np.empty(nmax)
    m = poly.shape[0]
    n = 0
    for row in range(y0, y1 + 1):
        y = row + 0.5
        for col in range(x0, x1 + 1):
            x = col + 0.5
            inside = False
            for i in range(m):
                ax, ay = poly[i, 0], poly[i, 1]
                bx, by = poly[(i + 1) % m, 0], poly[(i + 1) % m, 1]
                if (ay > y) != (by > y):
                    if x < ax + (y - ay) * (bx - ax) / (by - ay):
                        inside = not inside
            if not inside:
                continue
            px[n, 0], px[n, 1] = x, y
            du[n] = _polyline_distance(x, y, upper)
            dl[n] = _polyline_distance(x, y, lower)
            n += 1
    return px[:n], du[:n], dl[:n]


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _polyline_distance(x, y, chain):  # pragma: no cover
    best = np.inf
    for i in range(chain.shape[0] - 1):
        ax, ay = chain[i, 0], chain[i, 1]
        ex, ey = chain[i + 1, 0] - ax, chain[i + 1, 1] - ay
        t = ((x - ax) * ex + (y - ay) * ey) / max(ex * ex + ey * ey, 1e-12)
        t = min(max(t, 0.0), 1.0)
        dx, dy = x - (ax + t * ex), y - (ay + t * ey)
        d = dx * dx + dy * dy
        if d < best:
            best = d
    return np.sqrt(best)


def _inside_polygon(px, poly) -> np.ndarray:
    """Whether each point (N, 2) is inside the closed polygon (M, 2) (even-odd rule; the
    reference of :func:`_opening_pixels`)."""
    x, y = px[:, 0:1], px[:, 1:2]
    x0, y0 = poly[:, 0][None], poly[:, 1][None]
    x1, y1 = np.roll(poly[:, 0], -1)[None], np.roll(poly[:, 1], -1)[None]
    crosses = (y0 > y) != (y1 > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xc = x0 + (y - y0) * (x1 - x0) / (y1 - y0)
    return (crosses & (x < xc)).sum(axis=1) % 2 == 1


def _chain_distance(px, chain) -> np.ndarray:
    """Distance (N,) of points (N, 2) to the polyline ``chain`` (M, 2) (the reference of
    :func:`_opening_pixels`)."""
    a, b = chain[:-1][None], chain[1:][None]
    p = px[:, None, :]
    ab = b - a
    t = np.clip(((p - a) * ab).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    q = a + t[..., None] * ab
    return np.sqrt(((p - q) ** 2).sum(-1)).min(axis=1)


@numba.njit(cache=True, nogil=True)
def _sorted_by_x(px, bright, fixed):  # pragma: no cover
    """The pixels' x, y, brightness and fixed columns (m, N), in the (stable) order of x."""
    o = np.argsort(px[:, 0], kind="mergesort")
    n, m = fixed.shape
    xs, ys, b, f = np.empty(n), np.empty(n), np.empty(n), np.empty((m, n))
    for i in range(n):
        k = o[i]
        xs[i], ys[i], b[i] = px[k, 0], px[k, 1], bright[k]
        for j in range(m):
            f[j, i] = fixed[k, j]
    return xs, ys, b, f


@dataclass
class EyeSamples:
    """The pixels read of one eye's opening: centres ``px`` (N, 2) (x, y) px, brightness (N,)
    in [0, 1], and the fixed columns (N, m) of the brightness model (the plane and the bands),
    with ``proj`` the inverse of their normal matrix."""

    px: np.ndarray
    bright: np.ndarray
    fixed: np.ndarray
    proj: np.ndarray
    #: the pixels sorted by x for :func:`_gaze_rss`: (xs, ys, bright, fixed.T), made once
    _by_x: tuple | None = field(default=None, repr=False, compare=False)

    def by_x(self) -> tuple:
        """The pixels' x (N,), y (N,), brightness (N,) and fixed columns (m, N), sorted by x."""
        if self._by_x is None:
            self._by_x = _sorted_by_x(self.px, self.bright, self.fixed)
        return self._by_x

    @property
    def n(self) -> int:
        return len(self.px)

    def base_rss(self) -> float:
        """The residual sum of squares without an iris."""
        g = self.fixed.T @ self.bright
        return float(self.bright @ self.bright - g @ self.proj @ g)

    def checkerboard(self) -> EyeSamples:
        """Every other pixel (those whose column + row is even): the coarse grid's samples."""
        return EyeSamples(*_checkerboard(self.px, self.bright, self.fixed))


@numba.njit(cache=True, nogil=True)
def _sample_columns(img, px, du, dl, iris_px, upper_margin, lower_margin, band, luma,
                    scale):  # pragma: no cover  # fmt: skip
    """What :func:`_eye_samples_numpy` makes of the opening's pixels ``px`` (N, 2) and their
    distances to the margins ``du``, ``dl``: those far enough from the margins, their
    brightness, the fixed columns (the plane and the bands) and the inverse of their normal
    matrix (none kept: empty arrays)."""
    lim_u, lim_l = upper_margin * iris_px, lower_margin * iris_px
    n = 0
    for i in range(px.shape[0]):
        if du[i] > lim_u and dl[i] > lim_l:
            n += 1
    out = np.empty((n, 2))
    bright = np.empty(n)
    fixed = np.empty((n, 5))
    if n < 6:
        return out, bright, fixed, np.eye(5)
    j = 0
    mx = 0.0
    my = 0.0
    width = band * iris_px
    for i in range(px.shape[0]):
        if not (du[i] > lim_u and dl[i] > lim_l):
            continue
        x, y = px[i, 0], px[i, 1]
        out[j, 0], out[j, 1] = x, y
        r, c = int(y), int(x)
        v = float(img[r, c, 0]) * luma[0] + float(img[r, c, 1]) * luma[1]
        bright[j] = (v + float(img[r, c, 2]) * luma[2]) / scale
        fixed[j, 0] = 1.0
        fixed[j, 3] = np.exp(-du[i] / width)
        fixed[j, 4] = np.exp(-dl[i] / width)
        mx += x
        my += y
        j += 1
    mx /= n
    my /= n
    size = max(iris_px, 1.0)
    for j in range(n):
        fixed[j, 1] = (out[j, 0] - mx) / size
        fixed[j, 2] = (out[j, 1] - my) / size
    return out, bright, fixed, np.linalg.pinv(fixed.T @ fixed)


@numba.njit(cache=True, nogil=True)
def _checkerboard(px, bright, fixed):  # pragma: no cover
    """:meth:`EyeSamples.checkerboard`'s arrays: the pixels whose column + row is even, and
    the inverse of their fixed columns' normal matrix."""
    keep = np.empty(px.shape[0], dtype=np.bool_)
    for i in range(px.shape[0]):
        keep[i] = (int(np.floor(px[i, 0])) + int(np.floor(px[i, 1]))) % 2 == 0
    f = np.ascontiguousarray(fixed[keep])
    return px[keep], bright[keep], f, np.linalg.pinv(f.T @ f)


def _no_samples() -> EyeSamples:
    return EyeSamples(np.zeros((0, 2)), np.zeros(0), np.zeros((0, 5)), np.eye(5))


def _opening(frame, upper, lower):
    """The pixels of ``frame`` inside the opening bounded by ``upper`` and ``lower`` (see
    :func:`eye_samples`) and their distances to each margin (``_opening_pixels``), or None
    where the opening's box is off the frame."""
    poly = np.concatenate([upper, lower[::-1][1:-1]])
    h, w = frame.shape[:2]
    x0, y0 = np.maximum(np.floor(poly.min(axis=0)).astype(int) - 1, 0)
    x1, y1 = np.minimum(np.ceil(poly.max(axis=0)).astype(int) + 1, [w - 1, h - 1])
    if x1 < x0 or y1 < y0:
        return None
    return _opening_pixels(
        int(x0), int(y0), int(x1), int(y1), *(np.ascontiguousarray(a, dtype=np.float64)
                                              for a in (poly, upper, lower))
    )  # fmt: skip


def eye_samples(frame, upper, lower, iris_px: float, settings: GazeSettings) -> EyeSamples:
    """The pixels of ``frame`` (H, W, 3) inside the opening bounded by the lid margins
    ``upper`` and ``lower`` (each (M, 2) px, from corner to corner, the same corners), away from
    the margins by :attr:`GazeSettings.upper_margin` / ``lower_margin`` iris radii
    (``iris_px``); pixel (row, col) is read at (col + 0.5, row + 0.5)."""
    opening = _opening(frame, upper, lower)
    if opening is None:
        return _no_samples()
    px, du, dl = opening
    img = np.asarray(frame)
    px, bright, fixed, proj = _sample_columns(
        img, px, du, dl, float(iris_px), float(settings.upper_margin),
        float(settings.lower_margin), float(settings.band), LUMA,
        255.0 if img.dtype == np.uint8 else 1.0,
    )  # fmt: skip
    if len(px) < 6:
        return _no_samples()
    return EyeSamples(px, bright, fixed, proj)


def _eye_samples_numpy(frame, upper, lower, iris_px: float, settings: GazeSettings) -> EyeSamples:
    """The pixels of ``frame`` (H, W, 3) inside the opening bounded by the lid margins
    ``upper`` and ``lower`` (each (M, 2) px, from corner to corner, the same corners), away from
    the margins by :attr:`GazeSettings.upper_margin` / ``lower_margin`` iris radii
    (``iris_px``); pixel (row, col) is read at (col + 0.5, row + 0.5). (In numpy: the
    reference of :func:`eye_samples`.)"""
    opening = _opening(frame, upper, lower)
    if opening is None:
        return _no_samples()
    px, du, dl = opening
    keep = (du > settings.upper_margin * iris_px) & (dl > settings.lower_margin * iris_px)
    px, du, dl = px[keep], du[keep], dl[keep]
    if len(px) < 6:
        return _no_samples()
    rgb = np.asarray(frame)[px[:, 1].astype(int), px[:, 0].astype(int), :3]
    bright = rgb.astype(np.float64) @ LUMA / (255.0 if rgb.dtype == np.uint8 else 1.0)
    xy = (px - px.mean(axis=0)) / max(iris_px, 1.0)
    band = settings.band * iris_px
    fixed = np.column_stack(
        [np.ones(len(px)), xy[:, 0], xy[:, 1], np.exp(-du / band), np.exp(-dl / band)]
    )
    ata = fixed.T @ fixed
    proj = np.linalg.pinv(ata)
    return EyeSamples(px, bright, np.ascontiguousarray(fixed), proj)


# ------------------------------------------------------------------ the eye's socket, learned


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _bilinear(img, r, c):  # pragma: no cover
    """``img`` (H, W) at (row ``r``, column ``c``), NaN outside or where a corner is NaN."""
    h, w = img.shape
    if r < 0.0 or c < 0.0 or r > h - 1 or c > w - 1:
        return np.nan
    r0 = min(int(r), h - 2)
    c0 = min(int(c), w - 2)
    fr, fc = r - r0, c - c0
    return ((1 - fr) * ((1 - fc) * img[r0, c0] + fc * img[r0, c0 + 1])
            + fr * ((1 - fc) * img[r0 + 1, c0] + fc * img[r0 + 1, c0 + 1]))  # fmt: skip


@numba.njit(cache=True, nogil=True)
def _bilinear_at(img, rows, cols):  # pragma: no cover
    """:func:`_bilinear` at each of the points (N,)."""
    out = np.empty(rows.shape[0])
    for k in range(rows.shape[0]):
        out[k] = _bilinear(img, rows[k], cols[k])
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _project_head(points, rot, trans, f, cx, cy):  # pragma: no cover
    """Head-frame points (N, 3) mm through the pose (``rot``, ``trans``) and the pinhole
    camera (``f``, ``cx``, ``cy``) into the image (N, 2) px: ``camera.project(pose.apply(.))``."""
    n = points.shape[0]
    uv = np.empty((n, 2))
    for k in range(n):
        x, y, z = points[k, 0], points[k, 1], points[k, 2]
        qx = x * rot[0, 0] + y * rot[0, 1] + z * rot[0, 2] + trans[0]
        qy = x * rot[1, 0] + y * rot[1, 1] + z * rot[1, 2] + trans[1]
        qz = x * rot[2, 0] + y * rot[2, 1] + z * rot[2, 2] + trans[2]
        depth = max(-qz, 1e-6)
        uv[k, 0] = cx + f * qx / depth
        uv[k, 1] = cy - f * qy / depth
    return uv


@numba.njit(cache=True, nogil=True)
def _luma_crop(img, x0, y0, x1, y1, luma, scale):  # pragma: no cover
    """The luma (rows ``y0..y1``, columns ``x0..x1``) of the image ``img`` (H, W, >= 3),
    divided by ``scale``."""
    out = np.empty((y1 - y0 + 1, x1 - x0 + 1))
    for r in range(y0, y1 + 1):
        for c in range(x0, x1 + 1):
            v = float(img[r, c, 0]) * luma[0] + float(img[r, c, 1]) * luma[1]
            out[r - y0, c - x0] = (v + float(img[r, c, 2]) * luma[2]) / scale
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _sample_patch(img, x0, y0, uv, valid):  # pragma: no cover
    """:func:`_bilinear` of the crop ``img`` (its pixel (0, 0) the frame's (``x0``, ``y0``))
    at the image points ``uv`` (N, 2) (pixel centres at + 0.5), NaN where not ``valid``."""
    n = uv.shape[0]
    out = np.empty(n)
    for k in range(n):
        out[k] = _bilinear(img, uv[k, 1] - 0.5 - y0, uv[k, 0] - 0.5 - x0) if valid[k] else np.nan
    return out


@numba.njit(cache=True, nogil=True, error_model="numpy")
def _align_socket(img, x0, y0, points, rot, trans, f, cx, cy, tmpl, gx, gy, step_mm,
                  iris_c, iris_r, iterations, limit_mm, robust, prior_mm):  # pragma: no cover  # fmt: skip
    """The shift ``d`` (2,) mm (head frame x, y) by which the socket's grid ``points`` (N, 3),
    moved rigidly and projected by the pose (``rot``, ``trans``) and the camera (``f``,
    ``cx``, ``cy``), sample the image ``img`` (luma, its pixel (0, 0) the frame's
    (``x0``, ``y0``)) as the template ``tmpl`` (N,) shows them, up to a gain and an offset of
    brightness: Lucas-Kanade on the template's gradient (``gx``, ``gy`` (N,), per grid step
    ``step_mm``), the image resampled at each step (a pose misplaced by a translation is
    undone exactly, the skin's relief and all); points that fall within ``iris_r`` px of
    ``iris_c`` (the iris) or on NaN are not compared. Also the number of points compared
    (0: too few, or none converged)."""
    # the points compared at all (a template value and its gradient), in the camera frame
    # where the shift is nought, and the shift's directions there (head x and y)
    n = 0
    keep = np.empty(points.shape[0], dtype=np.int64)
    for k in range(points.shape[0]):
        if not (np.isnan(tmpl[k]) or np.isnan(gx[k]) or np.isnan(gy[k])):
            keep[n] = k
            n += 1
    q0 = np.empty((n, 3))
    tk = np.empty(n)
    gxk = np.empty(n)
    gyk = np.empty(n)
    for e in range(n):
        k = keep[e]
        x, y, z = points[k, 0], points[k, 1], points[k, 2]
        for a in range(3):
            q0[e, a] = rot[a, 0] * x + rot[a, 1] * y + rot[a, 2] * z + trans[a]
        tk[e], gxk[e], gyk[e] = tmpl[k], gx[k], gy[k]
    d = np.zeros(2)
    used = 0
    res = np.empty(n)
    samp = np.empty(n)
    gain, offset, scale, sigma = 1.0, 0.0, np.inf, 0.0
    ir2 = iris_r * iris_r
    for it in range(iterations):
        # the image at the moved points, and each point's residual against the template
        m = 0
        sx = rot[0, 0] * d[0] + rot[0, 1] * d[1]
        sy = rot[1, 0] * d[0] + rot[1, 1] * d[1]
        sz = rot[2, 0] * d[0] + rot[2, 1] * d[1]
        for e in range(n):
            samp[e] = np.nan
            depth = max(-(q0[e, 2] + sz), 1e-6)
            u = cx + f * (q0[e, 0] + sx) / depth
            v = cy - f * (q0[e, 1] + sy) / depth
            if (u - iris_c[0]) ** 2 + (v - iris_c[1]) ** 2 < ir2:
                continue
            p = _bilinear(img, v - 0.5 - y0, u - 0.5 - x0)
            if np.isnan(p):
                continue
            samp[e] = p
            res[m] = abs(p - gain * tk[e] - offset)
            m += 1
        if m < 30:
            return np.zeros(2), 0
        if it < 2:  # the residuals' robust scale (1.4826 median absolute), from the first two
            sigma = 1.4826 * np.median(res[:m])
            if it == 1:
                scale = sigma * robust
        # the normal equations (symmetric: the upper triangle summed)
        a00 = a01 = a02 = a03 = a11 = a12 = a13 = a22 = a23 = a33 = 0.0
        b0 = b1 = b2 = b3 = 0.0
        cg = gain / step_mm
        for e in range(n):
            p = samp[e]
            if np.isnan(p):
                continue
            t = tk[e]
            r = p - gain * t - offset
            wt = 1.0 if abs(r) <= scale else scale / abs(r)  # (Huber's)
            c0, c1 = cg * gxk[e], cg * gyk[e]
            w0, w1, w2 = wt * c0, wt * c1, wt * t
            a00 += w0 * c0
            a01 += w0 * c1
            a02 += w0 * t
            a03 += w0
            a11 += w1 * c1
            a12 += w1 * t
            a13 += w1
            a22 += w2 * t
            a23 += w2
            a33 += wt
            b0 += w0 * r
            b1 += w1 * r
            b2 += w2 * r
            b3 += wt * r
        # the prior on the shift (the unknowns are minus its step): lam |d - x|^2
        lam = m * sigma * sigma / (prior_mm * prior_mm * 4.0)
        ata = np.array([[a00 + 1e-9 + lam, a01, a02, a03], [a01, a11 + 1e-9 + lam, a12, a13],
                        [a02, a12, a22 + 1e-9, a23], [a03, a13, a23, a33 + 1e-9]])  # fmt: skip
        atb = np.array([b0 + lam * d[0], b1 + lam * d[1], b2, b3])
        step = np.linalg.solve(ata, atb)
        # (p ~ gain t + offset - gain grad . delta: the step moves the points by -delta)
        s0 = min(max(-step[0], -1.0), 1.0)
        s1 = min(max(-step[1], -1.0), 1.0)
        gain += step[2]
        offset += step[3]
        d[0] = min(max(d[0] + s0, -limit_mm), limit_mm)
        d[1] = min(max(d[1] + s1, -limit_mm), limit_mm)
        used = m
        if abs(s0) < 0.01 and abs(s1) < 0.01 and it > 1:
            break
    return d, used


class EyeSocket:
    """Where one eye's socket is in a frame, relative to where the fit put it: its appearance
    learned over the frames in the head frame, and each frame's offset found against it.

    The region around the eye (:attr:`GazeSettings.socket_half_mm` about the eyeball's
    centre, on a grid of :attr:`GazeSettings.socket_step_mm`, head frame) lies on the
    person's neutral skin and, inside the eye's opening, on the eyeball's sphere (what shows
    there: the sclera; with the skin's surface across the opening instead, the parallax of
    its 3-5 mm of depth at the head's 30 deg of yaw moved the offsets by 2 px). Each frame
    samples the image at the fit's projection of that grid (:meth:`sample`): a patch in which
    the fit's error of pose shows as a shift. The template is the mean of the patches
    (:meth:`learn`), each pixel over the frames where the iris did not cover it (the iris
    moves with the gaze, the socket does not): since the fit's errors change from frame to
    frame about a small mean, the template is registered to that mean. A frame's offset
    (:meth:`offset`, mm, head frame x and y) is the translation of its patch onto the
    template (Lucas-Kanade, the iris masked out), by which the eyeball's centre and the lids'
    margins are moved before the gaze is read.
    """

    def __init__(self, neutral, centre, upper, lower, settings):
        from scipy.spatial import cKDTree

        from myoface.face.eyes import EYE_RADIUS_MM

        st = settings
        v = np.asarray(neutral, dtype=np.float64)
        c = np.asarray(centre, dtype=np.float64)
        hx, hy = st.socket_half_mm
        xs = np.arange(c[0] - hx, c[0] + hx + 1e-9, st.socket_step_mm)
        ys = np.arange(c[1] - hy, c[1] + hy + 1e-9, st.socket_step_mm)
        x, y = np.meshgrid(xs, ys)
        near = (np.abs(v[:, 0] - c[0]) < hx + 10) & (np.abs(v[:, 1] - c[1]) < hy + 10)
        near &= v[:, 2] > c[2]
        pts = np.column_stack([x.ravel(), y.ravel()])
        # the skin's depth: inverse-distance weights of its nearest vertices (none beyond
        # 3 mm of one: off the face)
        dist, idx = cKDTree(v[near, :2]).query(pts, k=4)
        w = 1.0 / np.maximum(dist, 1e-6) ** 2
        z = (w * v[near, 2][idx]).sum(axis=1) / w.sum(axis=1)
        z = np.where(dist[:, 0] < 3.0, z, np.nan).reshape(x.shape)
        poly = np.concatenate([v[upper, :2], v[lower[::-1][1:-1], :2]])
        inside = _inside_polygon(pts, poly).reshape(x.shape)
        sphere = c[2] + np.sqrt(np.maximum(EYE_RADIUS_MM**2 - (x - c[0]) ** 2 - (y - c[1]) ** 2, 0))
        z = np.where(inside, sphere if st.socket_opening else np.nan, z)
        #: the grid's points (N, 3) mm, head frame, and those on the face (H, W) bool
        self.points = np.column_stack([pts, np.nan_to_num(z.ravel(), nan=c[2])])
        self.valid = np.isfinite(z)
        self._valid_flat = np.ascontiguousarray(self.valid.ravel())
        self.shape = x.shape
        self.settings = st
        self._sum = np.zeros(self.shape)
        self._count = np.zeros(self.shape)
        self._template = None  # (the mean, its gradients), kept until the next frame learnt
        self._frame, self._crop = None, None  # the last frame sampled, and its luma crop
        #: (:attr:`GazeSettings.socket_learn_moved`) the offset the frame's patch was sampled
        #: at, and the sum and count of those of the frames learnt
        self.pending = None
        self.moved_sum, self.moved_n = np.zeros(2), 0

    @property
    def ready(self) -> bool:
        """Whether the template has seen enough frames to align to."""
        return int((self._count >= self._min_frames).sum()) >= 50

    @property
    def _min_frames(self) -> int:
        """The frames a template pixel needs (one: the first frame's, when it is the anchor)."""
        st = self.settings
        return 1 if st.socket_template == "first" else int(st.socket_min_frames)

    def _luma(self, frame, uv):
        """The frame's luma about the image points ``uv`` (N, 2) (a margin of 2 px plus the
        largest offset), and its top-left pixel; None off the frame."""
        img = np.asarray(frame)
        m = 2 + int(np.ceil(self.settings.socket_max_mm * 2))  # (px per mm < 2 here)
        x0 = max(int(np.floor(uv[:, 0].min())) - m, 0)
        y0 = max(int(np.floor(uv[:, 1].min())) - m, 0)
        x1 = min(int(np.ceil(uv[:, 0].max())) + m, img.shape[1] - 1)
        y1 = min(int(np.ceil(uv[:, 1].max())) + m, img.shape[0] - 1)
        if x1 <= x0 + 1 or y1 <= y0 + 1:
            return None
        scale = 255.0 if img.dtype == np.uint8 else 1.0
        return _luma_crop(img, x0, y0, x1, y1, LUMA, scale), x0, y0

    def sample(self, frame, camera, pose, move=None) -> tuple[np.ndarray, np.ndarray]:
        """The frame's patch (H, W) (luma, bilinear; NaN off the face or the frame) at the
        projection of the grid by ``pose`` (the grid moved by ``move`` (2,) mm, head frame x
        and y, first), and the grid's image points (H, W, 2) px."""
        uv = self._project(camera, pose, move)
        got = self._luma(frame, uv)
        if move is None:
            self._crop, self._frame = got, frame  # (offset reads the same crop)
        if got is None:
            patch = np.full(len(uv), np.nan)
        else:
            img, x0, y0 = got
            patch = _sample_patch(img, x0, y0, uv, self._valid_flat)
        return patch.reshape(self.shape), uv.reshape(*self.shape, 2)

    def _project(self, camera, pose, move=None) -> np.ndarray:
        """The grid's points (moved by ``move`` (2,) mm, head frame) in the image (N, 2) px
        through ``pose`` and ``camera``."""
        pts = self.points
        if move is not None:
            pts = pts + np.array([move[0], move[1], 0.0])
        return _project_head(pts, np.asarray(pose.rotation, dtype=np.float64),
                             np.asarray(pose.translation_mm, dtype=np.float64),
                             float(camera.focal_px), float(camera.cx), float(camera.cy))  # fmt: skip

    def usable(self, uv, iris_centre, iris_radius_px) -> np.ndarray:
        """The patch's pixels (H, W) bool to learn from: on the face and off the iris read
        (:attr:`GazeSettings.socket_iris_px` beyond its radius)."""
        far = np.linalg.norm(uv - np.asarray(iris_centre), axis=-1)
        return self.valid & (far > iris_radius_px + self.settings.socket_iris_px)

    def learn(self, patch, usable) -> None:
        """Add a frame's patch (its usable pixels) to the template."""
        if self.settings.socket_template == "first" and self._count.any():
            return  # (anchored: the first frame learnt is the template, never updated)
        ok = usable & np.isfinite(patch)
        np.add(self._sum, patch, out=self._sum, where=ok)
        self._count += ok
        self._template = None

    def offset(self, frame, camera, pose, iris_centre, iris_radius_px) -> np.ndarray | None:
        """The shift (2,) mm, head frame (x, y), of the eye from where ``pose`` puts it: the
        grid moved by it and projected by ``pose`` sees the template
        (:func:`_align_socket`; the iris, centred at ``iris_centre`` px with radius
        ``iris_radius_px``, masked out); None while the template has too few frames or the
        frame too few of its points."""
        st = self.settings
        if not self.ready:
            return None
        if self._template is None:
            seen = (self._count >= self._min_frames) & self.valid
            tmpl = np.where(seen, self._sum / np.maximum(self._count, 1), np.nan)
            gy, gx = np.gradient(tmpl)
            self._template = tuple(np.ascontiguousarray(a.ravel()) for a in (tmpl, gx, gy))
        got = self._crop if frame is self._frame else None
        if got is None:
            got = self._luma(frame, self._project(camera, pose))
        if got is None:
            return None
        img, x0, y0 = got
        d, used = _align_socket(
            img, x0, y0, self.points, np.asarray(pose.rotation, dtype=np.float64),
            np.asarray(pose.translation_mm, dtype=np.float64), camera.focal_px, camera.cx,
            camera.cy, *self._template, st.socket_step_mm, np.asarray(iris_centre, float),
            iris_radius_px + st.socket_iris_px, int(st.socket_iterations), st.socket_max_mm,
            st.socket_robust, st.socket_prior_mm,
        )  # fmt: skip
        return None if used == 0 else d

    def agreement(self, frame, camera, pose, d, iris_centre, iris_radius_px) -> float:
        """The normalised cross-correlation of the template with the frame's patch sampled
        where the offset ``d`` (2,) mm puts the grid (its pixels on the face, seen by the
        template and off the iris, as :meth:`offset` compares them); NaN without a template."""
        st = self.settings
        if self._template is None:
            return float("nan")
        tmpl = self._template[0].reshape(self.shape)
        patch, uv = self.sample(frame, camera, pose, d)
        far = np.linalg.norm(uv - np.asarray(iris_centre), axis=-1)
        ok = np.isfinite(tmpl) & np.isfinite(patch) & (far > iris_radius_px + st.socket_iris_px)
        if ok.sum() < 30:
            return float("nan")
        a, b = tmpl[ok] - tmpl[ok].mean(), patch[ok] - patch[ok].mean()
        return float(a @ b / max(np.sqrt((a @ a) * (b @ b)), 1e-12))


# ------------------------------------------------------------------ the reader


def _grid(centre, step, half) -> tuple[np.ndarray, np.ndarray]:
    """(yaw, pitch) degrees of a square grid of ``step`` within ``half`` of ``centre``, inside
    +-:data:`MAX_GAZE_DEG`."""
    key = (float(step), float(half))
    offsets = _GRIDS.get(key)
    if offsets is None:
        a = np.arange(-half, half + 1e-9, step)
        offsets = _GRIDS[key] = tuple(x.ravel() for x in np.meshgrid(a, a, indexing="ij"))
    yaw, pitch = centre[0] + offsets[0], centre[1] + offsets[1]
    ok = (np.abs(yaw) <= MAX_GAZE_DEG) & (np.abs(pitch) <= MAX_GAZE_DEG)
    return yaw[ok], pitch[ok]


#: :func:`_grid`'s offsets by (step, half)
_GRIDS: dict = {}


@numba.njit(cache=True, nogil=True)
def _iris_at(centre, rot, yaw, pitch, f, cx, cy):  # pragma: no cover
    """The iris' centre (x, y) px and radius (px) for the gaze ``(yaw, pitch)`` degrees, head
    frame (as :func:`iris_ellipses`)."""
    y = np.radians(yaw)
    p = np.radians(pitch)
    hx, hy, hz = np.sin(y) * np.cos(p), np.sin(p), np.cos(y) * np.cos(p)
    gx = hx * rot[0, 0] + hy * rot[0, 1] + hz * rot[0, 2]
    gy = hx * rot[1, 0] + hy * rot[1, 1] + hz * rot[1, 2]
    gz = hx * rot[2, 0] + hy * rot[2, 1] + hz * rot[2, 2]
    x, y, _, _, major, _, _ = _ellipse_of(centre[0], centre[1], centre[2], gx, gy, gz,
                                          IRIS_DEPTH_MM, IRIS_RADIUS_MM, f, cx, cy)  # fmt: skip
    return x, y, major


@numba.njit(cache=True, nogil=True)
def _along_chain(v, chain, at):  # pragma: no cover
    """The points (len(at), 3) at the shares ``at`` of the polyline ``v[chain]``'s length."""
    m = chain.shape[0]
    s = np.zeros(m)
    for i in range(1, m):
        a, b = chain[i - 1], chain[i]
        d0, d1, d2 = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        s[i] = s[i - 1] + np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    s /= max(s[m - 1], 1e-9)
    out = np.empty((at.shape[0], 3))
    for k in range(3):
        out[:, k] = np.interp(at, s, v[chain, k])
    return out


@numba.njit(cache=True, nogil=True)
def _aperture_mm(v, upper, lower):  # pragma: no cover
    """The mean gap (mm) between the upper and the lower lid's margins (vertex chains) of the
    skin ``v`` (V, 3): their distance at 7 shares of their lengths, 0.2 to 0.8."""
    at = np.linspace(0.2, 0.8, 7)
    a, b = _along_chain(v, upper, at), _along_chain(v, lower, at)
    total = 0.0
    for i in range(at.shape[0]):
        d0, d1, d2 = a[i, 0] - b[i, 0], a[i, 1] - b[i, 1], a[i, 2] - b[i, 2]
        total += np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
    return total / at.shape[0]


def _percentile90(values) -> float:
    """``np.percentile(values, 90)`` (its linear interpolation), without numpy's overhead
    on the few values it is asked of here."""
    v = sorted(float(x) for x in values)
    n = len(v)
    q = 0.9
    virtual = (n * q + (1 + q * (1 - 1 - 1))) - 1
    i = min(max(int(np.floor(virtual)), 0), n - 1)
    j = min(i + 1, n - 1)
    t = virtual - np.floor(virtual)
    a, b = v[i], v[j]
    diff = b - a
    return float(b - diff * (1 - t) if t >= 0.5 else a + diff * t)


@dataclass
class _Eye:
    """One eye as the reader sees it in a frame."""

    side: str
    centre: np.ndarray  # (3,) mm, camera frame
    samples: EyeSamples
    iris_px: float
    upper: np.ndarray | None = None  # the lid margins (M, 2) px
    lower: np.ndarray | None = None
    coarse: EyeSamples | None = None  # every other pixel, for the coarse grid

    def rss(self, camera, rotation, yaw, pitch, settings, coarse: bool = False,
            pupil: bool = False) -> tuple:  # fmt: skip
        """The residual (K,) of each candidate, inf where its iris is not darker than the
        sclera, does not face the camera or misses the opening, the explained share (K,) and
        the iris' coefficient (K,); ``coarse``: on every other pixel; ``pupil``: with the
        pupil in the model."""
        if coarse and self.coarse is None:
            self.coarse = self.samples.checkerboard()
        s = self.coarse if coarse else self.samples
        rss, coef, base = _gaze_rss(
            *s.by_x(), s.proj, np.asarray(self.centre, dtype=np.float64),
            np.ascontiguousarray(rotation, dtype=np.float64), float(camera.focal_px),
            float(camera.cx), float(camera.cy), np.ascontiguousarray(yaw, dtype=np.float64),
            np.ascontiguousarray(pitch, dtype=np.float64), float(settings.edge_px), bool(pupil),
        )  # fmt: skip
        base = max(base, 1e-12)
        return rss, 1.0 - rss / base, coef


class GazeEstimator:
    """Each eye's gaze on the frames of a video, from the 3-D fit's head pose and skin (see the
    module's docstring).

    Parameters
    ----------
    face : FaceMesh in the default (MediaPipe) topology with the ``eye_l`` / ``eye_r``
        landmark groups (the model's face; never changed).
    settings : GazeSettings.

    Call :meth:`calibrate` with the person's neutral skin (head frame: the fit's
    ``neutral + identity_mm``), then :meth:`measure` on each frame in order; :meth:`reset`
    after frames without a reading (the temporal filter starts again).
    """

    def __init__(self, face, settings: GazeSettings | None = None):
        self.settings = settings or GazeSettings()
        self._eyes = {}
        for side, group in EYES:
            loop = eye_loop(face, group)
            if loop is None or group not in face.landmarks:
                raise MyofaceValueError(f"the gaze needs the face's {group!r} eye opening")
            ring = np.asarray(face.landmarks[group], dtype=np.int64)
            self._eyes[side] = (loop, *self._chains(face.vertices, ring))
        self.centres_mm: dict[str, np.ndarray] = {}
        #: each eye's socket (:class:`EyeSocket`, when :attr:`GazeSettings.socket`)
        self.sockets: dict[str, EyeSocket] = {}
        #: each eye's last offset of its socket (mm, head frame x and y; None: none found)
        self.offsets: dict[str, np.ndarray | None] = {"l": None, "r": None}
        #: each eye's last agreement of its socket with the template (NCC, when
        #: :attr:`GazeSettings.socket_agreement` is set; None: not measured)
        self.agreements: dict[str, float | None] = {"l": None, "r": None}
        #: each eye's opening as the fit put it in the last frame read, before its socket's
        #: offset: the mean of its lid margins' image points (px; the benchmark's detail
        #: compares it with the truth's)
        self.openings: dict[str, np.ndarray | None] = {"l": None, "r": None}
        self.aperture_mm: dict[str, float] = {}
        self.calibrate(face.vertices)
        self.smoother = GazeSmoother(self.settings)
        #: the last frame's gaze read (both eyes' mean), None after a frame without one
        self._last: tuple | None = None
        #: each eye's last contrasts read (for :attr:`GazeSettings.closed_contrast`)
        self._contrasts: dict[str, list] = {"l": [], "r": []}
        #: each eye's frames read since its lids were last said closed (None: not since the
        #: start or a reset), for :attr:`GazeSettings.reopen_frames`
        self._since_closed: dict[str, int | None] = {"l": None, "r": None}
        #: where the time goes: frames read and the seconds they took
        self.timings = {"frames": 0, "seconds": 0.0}

    @staticmethod
    def _chains(vertices, ring) -> tuple[np.ndarray, np.ndarray]:
        """The opening's margin ``ring`` (vertex indices in order around it) split at its two
        corners (its extremes in x) into the upper and the lower lid's chains, each from the
        first corner to the second."""
        x = vertices[ring, 0]
        i, j = sorted((int(np.argmin(x)), int(np.argmax(x))))
        one = ring[i : j + 1]
        other = np.concatenate([ring[j:], ring[: i + 1]])[::-1]
        if vertices[one, 1].mean() < vertices[other, 1].mean():
            one, other = other, one
        return one, other

    def calibrate(self, neutral) -> None:
        """Take the person's neutral skin (V, 3) mm, head frame: each eyeball's centre
        (:func:`~myoface.face.eyes.eyeball_center`, where the renderer draws it for that face)
        and the open lids' aperture."""
        v = np.asarray(neutral, dtype=np.float64)
        for side, (loop, upper, lower) in self._eyes.items():
            self.centres_mm[side] = eyeball_center(v, loop)
            self.aperture_mm[side] = self._aperture(v, upper, lower)
            if self.settings.socket:
                self.sockets[side] = EyeSocket(v, self.centres_mm[side], upper, lower,
                                               self.settings)  # fmt: skip

    @staticmethod
    def _aperture(v, upper, lower) -> float:
        """The mean gap (mm) between the upper and the lower lid's margins of skin ``v``
        (:func:`_aperture_mm`)."""
        return float(_aperture_mm(np.ascontiguousarray(v, dtype=np.float64), upper, lower))

    def reset(self) -> None:
        """Forget the past readings (after a frame without a face)."""
        self.smoother.reset()
        self._last = None
        self._since_closed = {"l": None, "r": None}

    def read(self, frame, camera, pose, shape, points=None) -> Gaze:
        """Each eye's reading on ``frame`` (H, W, 3) for the fit's ``pose``
        (:class:`~myoface.analysis.camera.HeadPose`) and ``shape`` (V, 3) mm, head frame (the
        fitted skin, its lids too), through ``camera``; ``points``: MediaPipe's (V, 3) points
        (the lid margins when :attr:`GazeSettings.lids` is ``"landmarks"``). Unfiltered
        (:meth:`measure` filters it)."""
        import time

        t0 = time.perf_counter()
        st = self.settings
        rot = np.asarray(pose.rotation, dtype=np.float64)
        shape = np.asarray(shape, dtype=np.float64)
        if st.lids == "landmarks" and points is None:
            raise MyofaceValueError("lids='landmarks' needs MediaPipe's points")
        self.offsets = {"l": None, "r": None}
        self.agreements = {"l": None, "r": None}
        self.openings = {"l": None, "r": None}
        out: dict[str, EyeGaze] = {}
        reopening: set[str] = set()  # (eyes read but withheld: their lids reopen)
        opening: dict[str, float] = {}  # each eye's aperture, of the open one's
        eyes: list[_Eye] = []
        for side, (_, upper, lower) in self._eyes.items():
            centre, up2, lo2 = self._placement(side, camera, pose, shape, points)
            self.openings[side] = np.concatenate([up2, lo2]).mean(axis=0)
            opening[side] = self._aperture(shape, upper, lower) / self.aperture_mm[side]
            if opening[side] < st.closed_ratio:
                out[side] = EyeGaze(state="closed")
                continue
            axis = rot[:, 2]
            view = -centre / np.linalg.norm(centre)
            if np.degrees(np.arccos(np.clip(axis @ view, -1.0, 1.0))) > st.max_view_deg:
                out[side] = EyeGaze(state="hidden")
                continue
            iris_px = IRIS_RADIUS_MM * camera.focal_px / max(-centre[2], 1e-6)
            samples = eye_samples(frame, up2, lo2, iris_px, st)
            if samples.n < st.min_pixels:
                out[side] = EyeGaze(state="hidden")
                continue
            eyes.append(_Eye(side, centre, samples, iris_px, up2, lo2))
        if eyes:
            start = self._coarse(eyes, camera, rot)
            patches: dict[str, tuple] = {}
            if st.socket and start is not None:
                # each eye moved to where its socket is, then the coarse grid again there
                for i, e in enumerate(eyes):
                    if opening[e.side] < st.socket_open:  # (the lids cross the template)
                        continue
                    eyes[i], patches[e.side] = self._socket(
                        e, frame, camera, pose, shape, points, start
                    )
                if any(self.offsets[e.side] is not None for e in eyes):
                    again = self._coarse(eyes, camera, rot, start, st.socket_window_deg)
                    start = start if again is None else again
            for e in eyes:
                out[e.side] = self._closed_by_contrast(e.side, self._refine(e, camera, rot, start))
                if self._reopening(e.side, out[e.side]):
                    reopening.add(e.side)
                    out[e.side] = replace(out[e.side], yaw_deg=np.nan, pitch_deg=np.nan,
                                          state="closed")  # fmt: skip
                patch = patches.get(e.side)
                if patch is not None and self._wide_open(e.side, out[e.side], opening[e.side]):
                    self._learn(e, camera, rot, out[e.side], *patch)
        for side in ("l", "r"):  # (the lids said closed on this frame, for the next ones')
            n = self._since_closed[side]
            shut = out[side].state == "closed" and side not in reopening
            self._since_closed[side] = 0 if shut else (None if n is None else n + 1)
        if st.yoke_pitch and out["l"].ok and out["r"].ok:
            out = self._yoked(out)
        read = [out[s] for s in ("l", "r") if s in out and out[s].ok]
        self._last = (
            (np.mean([e.yaw_deg for e in read]), np.mean([e.pitch_deg for e in read]))
            if read else None
        )  # fmt: skip
        self.timings["frames"] += 1
        self.timings["seconds"] += time.perf_counter() - t0
        return Gaze(out["l"], out["r"])

    def _coarse(self, eyes: list[_Eye], camera, rot, centre=(0.0, 0.0),
                half: float = MAX_GAZE_DEG) -> tuple | None:  # fmt: skip
        """The coarse grid's best gaze for the eyes together (their residuals relative to each
        eye's own without an iris; each eye is then refined alone around it), None if none;
        the grid within ``half`` (deg) of ``centre``."""
        st = self.settings
        yaw, pitch = _grid(centre, st.coarse_deg, half)
        total = np.zeros(len(yaw))
        for e in eyes:
            # (the first, full grid finds the basin on the iris alone: a step of it moves the
            # pupil, 2.8 px across, by 1.1 px)
            pupil = st.pupil == "all" and half < MAX_GAZE_DEG
            rss = e.rss(camera, rot, yaw, pitch, st, coarse=True, pupil=pupil)[0]
            total += rss / max(e.coarse.base_rss(), 1e-12)
        if self._last is not None and st.prior > 0:
            # the last frame's gaze breaks near-ties between far apart minima
            d2 = (yaw - self._last[0]) ** 2 + (pitch - self._last[1]) ** 2
            total = total + st.prior * len(eyes) * d2 / MAX_GAZE_DEG**2
        k = int(np.argmin(total))
        return (float(yaw[k]), float(pitch[k])) if np.isfinite(total[k]) else None

    def _placement(self, side, camera, pose, shape, points) -> tuple:
        """Where the fit puts eye ``side`` in the frame: its eyeball's centre (3,) mm, camera
        frame, and its upper and lower lid margins (each (M, 2) px, corner to corner). (The
        benchmark's oracle swaps replace it with the truth's, :mod:`myoface.bench.gaze`.)"""
        _, upper, lower = self._eyes[side]
        centre = pose.apply(self.centres_mm[side][None])[0]
        if self.settings.lids == "landmarks":
            up2, lo2 = (np.asarray(points)[c, :2] for c in (upper, lower))
        else:
            up2, lo2 = (camera.project(pose.apply(shape[c])) for c in (upper, lower))
        return centre, up2, lo2

    def _iris_image(self, eye: _Eye, camera, rot, yaw, pitch) -> tuple[np.ndarray, float]:
        """The iris' centre (2,) px and radius (px) in the image for the gaze ``(yaw, pitch)``."""
        c = np.asarray(eye.centre, dtype=np.float64)
        x, y, major = _iris_at(c, np.ascontiguousarray(rot, dtype=np.float64), float(yaw),
                               float(pitch), float(camera.focal_px), float(camera.cx),
                               float(camera.cy))  # fmt: skip
        return np.array([x, y]), float(major)

    def _socket(self, eye: _Eye, frame, camera, pose, shape, points, start) -> tuple:
        """``eye`` moved by its socket's offset in ``frame`` (:class:`EyeSocket`: the eyeball's
        centre and the lids' margins; ``eye`` itself while the template is too young), and the
        frame's patch and its pixels' image points (for :meth:`_learn`). The iris, masked out
        of the comparison, is where the coarse grid's gaze ``start`` puts it."""
        st = self.settings
        rot = np.asarray(pose.rotation, dtype=np.float64)
        sock = self.sockets[eye.side]
        sock.pending = None
        patch, uv = sock.sample(frame, camera, pose)
        iris_c, iris_r = self._iris_image(eye, camera, rot, *start)
        d = raw = sock.offset(frame, camera, pose, iris_c, iris_r)
        if d is None:
            return eye, (patch, uv)
        if st.socket_learn_moved and st.socket_recentre and sock.moved_n > 0:
            # (the template's patches were sampled where their offsets put them: its place is
            # theirs, and their mean is taken off to keep it at the fit's mean, not its own)
            d = raw - sock.moved_sum / sock.moved_n
        if st.socket_agreement > 0:
            # the socket's surroundings as the template has them, or changed (a brow raised,
            # a squint: the skin about the eye moves, the eyeball does not): then the pose's
            ncc = self.agreements[eye.side] = sock.agreement(frame, camera, pose, d, iris_c, iris_r)
            if not ncc >= st.socket_agreement:
                return eye, (patch, uv)
        move = np.array([d[0], d[1], 0.0])
        centre = pose.apply((self.centres_mm[eye.side] + move)[None])[0]
        _, upper, lower = self._eyes[eye.side]
        if st.lids == "landmarks":
            shift = camera.project(centre[None])[0] - camera.project(eye.centre[None])[0]
            up2, lo2 = eye.upper + shift, eye.lower + shift
        else:
            up2, lo2 = (camera.project(pose.apply(shape[c] + move)) for c in (upper, lower))
        samples = eye_samples(frame, up2, lo2, eye.iris_px, st)
        if samples.n < st.min_pixels:
            return eye, (patch, uv)
        self.offsets[eye.side] = d
        if st.socket_learn_moved:  # (the template learns the patch where the socket found it)
            patch, uv = sock.sample(frame, camera, pose, raw)
            sock.pending = raw
        return _Eye(eye.side, centre, samples, eye.iris_px, up2, lo2), (patch, uv)

    def _wide_open(self, side: str, read: EyeGaze, opening: float) -> bool:
        """Whether a frame's eye is open enough to teach its socket's template: read, its
        lids at least :attr:`GazeSettings.socket_open` of their open aperture apart and its
        iris at least that share of its usual contrast (the lids close over the template's
        region in a blink)."""
        st = self.settings
        if not read.ok or opening < st.socket_open:
            return False
        past = self._contrasts[side]
        usual = _percentile90(past) if past else 0.0
        return abs(read.contrast) >= st.socket_open * usual

    def _learn(self, eye: _Eye, camera, rot, read: EyeGaze, patch, uv) -> None:
        """The frame's patch into the socket's template, off the iris read."""
        sock = self.sockets[eye.side]
        iris_c, iris_r = self._iris_image(eye, camera, rot, read.yaw_deg, read.pitch_deg)
        sock.learn(patch, sock.usable(uv, iris_c, iris_r))
        if sock.pending is not None:
            sock.moved_sum = sock.moved_sum + sock.pending
            sock.moved_n += 1

    def _refine(self, eye: _Eye, camera, rot, start, fine=None) -> EyeGaze:
        st = self.settings
        fine = st.fine if fine is None else fine
        if start is None:
            return EyeGaze(state="not_found")
        best, explained, contrast = start, float("nan"), float("nan")
        for i, (step, half) in enumerate(fine):
            yaw, pitch = _grid(best, step, half)
            last = i == len(fine) - 1  # (the steps before the last on every other pixel)
            pupil = st.pupil == "all" or (st.pupil == "last" and last)
            rss, expl, coef = eye.rss(camera, rot, yaw, pitch, st, coarse=not last, pupil=pupil)
            k = int(np.argmin(rss))
            if not np.isfinite(rss[k]):
                return EyeGaze(state="not_found")
            best, explained, contrast = (
                (float(yaw[k]), float(pitch[k])),
                float(expl[k]),
                float(coef[k]),
            )
        if not explained >= st.min_explained:
            return EyeGaze(state="not_found", explained=explained, contrast=contrast)
        return EyeGaze(best[0], best[1], "ok", explained, contrast)

    def _reopening(self, side: str, eye: EyeGaze) -> bool:
        """Whether ``eye``'s reading is within :attr:`GazeSettings.reopen_frames` frames after
        its lids were said closed (the lids reopen over a few frames, the iris half covered):
        then it is withheld, ``closed``."""
        n = self._since_closed[side]
        return eye.ok and n is not None and n < int(self.settings.reopen_frames)

    @staticmethod
    def _yoked(out: dict) -> dict:
        """Both eyes read: their pitch replaced by its mean (the eyes' vertical rotations are
        yoked, see :attr:`GazeSettings.yoke_pitch`)."""
        pitch = 0.5 * (out["l"].pitch_deg + out["r"].pitch_deg)
        return {s: replace(e, pitch_deg=pitch) for s, e in out.items()}

    def _closed_by_contrast(self, side: str, eye: EyeGaze) -> EyeGaze:
        """``eye``, or ``closed`` when what was read (an iris, or too faint a one) is too faint
        against the eye's usual contrast (:attr:`GazeSettings.closed_contrast`; the usual from
        the readings it was read on, this one with them)."""
        if not np.isfinite(eye.contrast):
            return eye
        past = self._contrasts[side]
        c = abs(eye.contrast)
        usual = _percentile90([*past, c])
        if c < self.settings.closed_contrast * usual:
            return EyeGaze(state="closed", explained=eye.explained, contrast=eye.contrast)
        if eye.ok:
            past.append(c)
            del past[: max(0, len(past) - int(self.settings.contrast_frames))]
        return eye

    def measure(self, frame, camera, pose, shape, points=None) -> Gaze:
        """:meth:`read`, filtered in time (:class:`GazeSmoother`), with where each eye was
        placed (:attr:`Gaze.placed`)."""
        g = self.smoother.update(self.read(frame, camera, pose, shape, points))
        placed = {s: (self.offsets.get(s), self.openings.get(s)) for s in ("l", "r")}
        return replace(g, placed=placed)

    def describe(self) -> dict:
        """For analysis.json: the settings and the time a frame's reading took."""
        from dataclasses import asdict

        n = self.timings["frames"]
        return {
            "settings": asdict(self.settings),
            "ms_per_frame": None if n == 0 else 1e3 * self.timings["seconds"] / n,
        }


class GazeSmoother:
    """A causal filter of each eye's readings that keeps saccades: the output is the weighted
    mean of the newest reading and up to :attr:`GazeSettings.smooth_frames` before it (of the
    same fixation: every one read), each weighted by ``exp(-d^2 / (2 s^2))`` with ``d`` its
    angular distance (deg) from the newest and ``s`` :attr:`GazeSettings.smooth_deg`. A jump
    of ``4 s`` between frames gives the older readings a weight of e^-8: the saccade passes
    whole, on its frame. An eye that is not read empties its history."""

    def __init__(self, settings: GazeSettings | None = None):
        self.settings = settings or GazeSettings()
        self._past: dict[str, list] = {"l": [], "r": []}

    def reset(self) -> None:
        for v in self._past.values():
            v.clear()

    def update(self, gaze: Gaze) -> Gaze:
        out = {}
        for side in ("l", "r"):
            e = gaze.eye(side)
            past = self._past[side]
            if not e.ok:
                past.clear()
                out[side] = e
                continue
            now = np.array([e.yaw_deg, e.pitch_deg])
            past.append(now)
            del past[: max(0, len(past) - 1 - int(self.settings.smooth_frames))]
            p = np.array(past)
            d2 = ((p - now) ** 2).sum(axis=1)
            w = np.exp(-0.5 * d2 / self.settings.smooth_deg**2)
            m = (w[:, None] * p).sum(axis=0) / w.sum()
            out[side] = EyeGaze(float(m[0]), float(m[1]), "ok", e.explained, e.contrast)
        return Gaze(out["l"], out["r"])


def gaze_camera_vectors(pose, gaze: Gaze) -> dict[str, np.ndarray | None]:
    """Each eye's gaze as a unit vector (3,) in the camera frame of ``pose`` (myoface's: x right,
    y up, z towards the viewer), None where the eye was not read."""
    rot = np.asarray(pose.rotation, dtype=np.float64)
    out = {}
    for side in ("l", "r"):
        e = gaze.eye(side)
        out[side] = rot @ gaze_directions(e.yaw_deg, e.pitch_deg) if e.ok else None
    return out
