"""How sure: the measurement uncertainty of the ISO 230-2 figures, the fitted model's
parameters and the compensation table's values, by the Monte Carlo method of JCGM 101:2008
over a budget in the structure of ISO 230-2:2014 Annex A and ISO/TR 230-9
(``feedaxis uncertainty``), and the correction of a case to 20 °C.

- :mod:`.budget` the budget file, its contributions and their documented defaults,
- :mod:`.distributions` the input quantities' distributions,
- :mod:`.correction` the correction to 20 °C (a pure function of a case; light to import,
  the commands that take ``--correct-to-20C`` parse it),
- :mod:`.positioning` what each input does to a positioning test, and the outputs,
- :mod:`.engine` the Monte Carlo method itself (chunks, intervals, adaptive, contributions),
- :mod:`.evaluation` :func:`~.evaluation.evaluate`, the whole evaluation of a case,
- :mod:`.text` and :mod:`.page` the result for the terminal and as an HTML page.
"""
