"""The paper and the comparison with it: published values (:mod:`.data`), the backends
in the paper's coordinates (:mod:`.compare`), the named effects (:mod:`.effects`), the
figures (:mod:`.figures`) and the report (:mod:`.report`, :mod:`.document`), whose
sections are one module each (:mod:`.opening`, :mod:`.matrices`, :mod:`.summary`,
:mod:`.tables`, :mod:`.explained`, :mod:`.differences`, :mod:`.weight`, :mod:`.beams`,
:mod:`.parameters`)."""
