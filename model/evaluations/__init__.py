"""The source documents' own evaluations, one file per filter (``model/evaluations/NAME.py``),
each with its ``EVALUATION`` (:class:`~kfpga.core.spec.Evaluation`), which the filter's spec names
and ``kfpga evaluate NAME`` runs."""
