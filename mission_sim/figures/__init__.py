"""Figures (matplotlib, Agg backend; nothing is shown on screen). Only the CLI imports these;
no physics, world or study module does.

=============  ==============================================================
``common``     the Agg backend and :func:`save_figure`
``paper``      Fig. 6: V2* references and I2 envelopes (``dronewpt paper``)
``switching``  raw switching-level waveforms (``dronewpt paper --model switching``)
``mission``    trajectory, Lm(t), I2 envelope, SoC, power; the Lm(x, y) map
``replay``     logged against modelled power of a replayed flight log
``refly``      a logged flight re-flown with charging pads (``replay LOG --pads FILE``)
``sizing``     worst-case |i2|, required rating and rectifier mass per policy
``calibrate``  logged against calibrated / default modelled power, vs time and speed, residuals
``worker``     the mission figures drawn by a forked process that imports matplotlib during the run
=============  ==============================================================
"""

#: trajectory samples beyond which the mission figures draw the path from the stored (thinned) time
#: series, not from the trajectory (which a long mission does not hold): :mod:`.mission`, :mod:`.worker`
PATH_SAMPLES = 50_000
