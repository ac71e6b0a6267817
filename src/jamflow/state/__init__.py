"""What a packing is: centres, sizes, box and bodies (:class:`Packing`, :class:`Links`, :class:`ShapeTable`)."""
