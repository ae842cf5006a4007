"""Tuning constants of the engine, in one place, each with what it trades off.

Lengths in metres, speeds in m/s, times in seconds. None of these is a user setting: the 2008
settings (steps per second, resolve iterations, octree depth, freezing thresholds) live in the
scene's `settings` and keep their 2008 meaning.
"""

# Contacts are generated up to this far apart (plus the distance the bodies can close in one
# step), so a resting contact exists before bodies touch and a fast body meets its contact before
# it can pass through (speculative contacts). Larger costs solver rows; smaller lets bodies jitter.
CONTACT_MARGIN = 0.02

# Penetration allowed without correction. Correcting every micrometre makes resting contacts
# flicker in and out; too much slop makes boxes visibly sink into each other.
LINEAR_SLOP = 0.005

# Fraction of the remaining penetration removed per step by the position (split-impulse) pass.
# 1.0 would remove it at once and overshoot in stacks; lower leaves boxes sunk for longer.
POSITION_CORRECTION = 0.2

# Cap on the speed the position pass may use to push bodies apart, so a deep overlap (a body
# spawned inside another) separates over a few steps instead of exploding.
MAX_CORRECTION_SPEED = 2.0

# Shock propagation sweeps at most this many times over the support points of one body (against
# fixed supports), and stops once a sweep changes no velocity by more than SHOCK_TOLERANCE. What
# a body's sweeps leave unsolved its upper neighbours inherit, so the error adds up with a
# stack's height. Cold-started, with 4 sweeps a 30-box tower still swayed 3 cm, with 8 a 20-row
# pyramid's top 11 mm, with 16 neither moved 5 mm. Warm-started (each point's one-sided impulse
# carried from the step before), over 20 s without freezing the pyramid drifted 15.8 mm with
# 6 sweeps, 4.1 with 8, 1.6 with 10 and 3.0 with 16 (chaotic), every other issue-20 stack under
# 0.4 mm from 8 on; each sweep costs the loose pile's landing step ~0.1 ms. A tolerance of
# 1e-5 m/s let that tower creep 1.2 cm.
SHOCK_SWEEPS = 10
SHOCK_TOLERANCE = 1.0e-7  # m/s

# Relative normal speeds below this do not bounce. Without it, the velocity that gravity adds in
# a step would be reflected by elasticity and resting stacks would never come to rest.
RESTITUTION_THRESHOLD = 0.2

# A contact point slipping slower than this when a step begins is sticking: static friction
# holds it. Faster, it slides with dynamic friction. Too low and resting boxes on slopes creep.
STICKING_SPEED = 0.01

# Separation-axis choice: an edge-edge axis must separate better than the best face axis by this
# much before it wins; faces give 4-point manifolds and keep resting boxes from rocking.
EDGE_AXIS_TOLERANCE = 0.005

# A playground triangle's own face gives the contact normal whenever the box is sunk at most this
# far below the triangle's plane, so boxes slide across the seams between triangles instead of
# catching on an edge or side axis that points into the neighbouring triangle. Larger would lift
# a box standing beside a step lower than this onto it; smaller than resting penetration would
# let seams catch again.
SEAM_TOLERANCE = 0.02

# Two manifold points (in the first body's frame) closer than this are the same contact from one
# step to the next, so last step's impulse warm-starts this step's solve.
WARM_START_MATCH_DISTANCE = 0.03

# A frozen body is woken by a touching awake body whose contact-point speed exceeds this many
# times the freezing linear speed threshold: a box sliding over a frozen pile wakes it, a box
# merely resting on it does not.
WAKE_SPEED_FACTOR = 2.0
# ... and by one that overlaps it deeper than this (m): the overlap is pushed apart by position
# correction alone, which moves nothing at a speed, so a box grown inside a frozen tower jammed
# the boxes between it and the frozen top ones 0.8 m into each other for good. Resting
# contacts settle at about LINEAR_SLOP.
WAKE_DEPTH = 3.0 * LINEAR_SLOP

# A frozen body enters the (rarely rebuilt) static index once this many bodies wait for it, or a
# fraction of the indexed ones; until then it is re-indexed each step like a moving body.
STATIC_REINDEX_MIN_PENDING = 32
STATIC_REINDEX_PENDING_FRACTION = 0.1

# The octree never goes deeper than this, whatever `octree_depth` says: Morton codes of 10 bits
# per axis fit comfortably in int64 keys together with their level offset.
MAX_OCTREE_DEPTH = 10
