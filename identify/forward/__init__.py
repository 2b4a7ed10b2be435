"""Forward models of the identification (:mod:`itr_identify.forward.model`)."""
