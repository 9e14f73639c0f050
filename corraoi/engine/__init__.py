"""The engine: runs of one policy simulated block by block, in compiled code or plain Python,
as :class:`~corraoi.engine.block.SlotBlock` s."""
