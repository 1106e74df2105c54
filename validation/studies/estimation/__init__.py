"""Estimators run on the reference simulation (the truth), by concern:

* :mod:`.workflow`: ``estimate(request) -> report``, the one entry point of the command line
  and the notebook; the request keeps the calibration (what the filter knows) apart from the
  truth (a scenario, a recording, a drive's shifts);
* :mod:`.uio`: the UIO per phase of a shift (thesis 4.4);
* :mod:`.modes`: the element modes (slip, stick) the EKF switches between, detected and true;
* :mod:`.setup`: the EKF's (4.3) set-up on a simulated shift (:class:`~.setup.EkfSetup`);
* :mod:`.loop`: the EKF run over the measurements (:func:`~.loop.filter_run`) and its result;
* :mod:`.bounds`: the posterior Cramér–Rao bound matched to the EKF;
* :mod:`.montecarlo`: the EKF's Monte-Carlo evaluation against that bound;
* :mod:`.euio`: the extended UIO (4.5), the road load as unknown input;
* :mod:`.report`, :mod:`.plots`: the results as CSV, text and figures.
"""
